"""``nsdrake drive`` (its command line, nsdrake.cli.main) with one fault planted: the
controller's step is not told that the robot adds g(q), so its actuator limits bound τ
and not the command τ − g(q) that is sent (the limiter of before issue 43's fix). With a
payload whose gravity is beyond what a joint may be sent, the first command is beyond the
Panda's limits, and only the last gate before the wire stands between it and the robot
(tests/driver/test_udp.py). Arguments: those of ``nsdrake``."""

from __future__ import annotations

import sys

import nsdrake.driver.controller_side as controller_side
from nsdrake.cli import main
from nsdrake.control.step import ControllerStep


class LimitsOnTau(ControllerStep):
    def __init__(self, **arguments):
        super().__init__(**{**arguments, "robot_adds_gravity": False})


if __name__ == "__main__":
    controller_side.ControllerStep = LimitsOnTau
    sys.exit(main(sys.argv[1:]))
