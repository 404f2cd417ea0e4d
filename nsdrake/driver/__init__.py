"""nsdrake drive: the controller behind a Franka Panda's LCM driver, and a simulated driver.

A layer between :mod:`nsdrake.reporting` and :mod:`nsdrake.studies`. The controller side
(:mod:`nsdrake.driver.controller_side`, :mod:`nsdrake.driver.loop`) answers each
``lcmt_panda_status`` with one ``lcmt_panda_command`` in torque mode; the simulated driver
(:mod:`nsdrake.driver.simulated_driver`) is the scenario's station behind Drake's
``PandaCommandReceiver`` and ``PandaStatusSender``; :mod:`nsdrake.driver.run` runs them.
"""
