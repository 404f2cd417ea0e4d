"""The realism ladder (Section 4's real robot): the switches of each rung and where its
defaults come from (``config``), and how each rung plugs into the station (``wiring``,
``model_error``)."""
