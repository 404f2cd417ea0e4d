"""nsdrake drive: the controller behind a Franka Panda's LCM driver, and a simulated driver.

A layer between :mod:`nsdrake.reporting` and :mod:`nsdrake.studies`. The controller side
(:mod:`nsdrake.driver.controller_side`, :mod:`nsdrake.driver.loop`, on the bus of
:mod:`nsdrake.driver.bus`, the messages read and written in place by
:mod:`nsdrake.driver.wire`) answers the newest ``lcmt_panda_status`` with one
``lcmt_panda_command`` in torque mode, one ``ControllerStep`` call per status; the
simulated driver (:mod:`nsdrake.driver.simulated_driver`) is the scenario's station behind
the Panda's messages (encoded in place as Drake's ``PandaStatusSender`` fills them), free-running as
drake-franka-driver in :mod:`nsdrake.driver.serve`; :mod:`nsdrake.driver.run` runs them.
"""
