"""nsdrake drive's reference (PlainSurfaceReference) keeps the first contact's time through
a loss and a return of contact, as SurfaceReferenceSystem does (issue 37): the circle of
panda_wipe's reference starts ``delay`` after the FIRST contact and goes on from there
when contact is found again. (tests/experiment/test_contact_loss.py compares the two
through a loss with SlideAndPress, whose path does not depend on the first contact.)"""

from __future__ import annotations

import numpy as np
import pytest
from models import PANDA_CIRCLE
from pydrake.systems.analysis import Simulator

from nsdrake.experiment.reference import CircleOnSurface, PlainSurfaceReference
from nsdrake.experiment.reference_system import SurfaceReferenceSystem

PERIOD, THRESHOLD = 1e-3, 0.5
CONTACT, LOST, AGAIN, END = 0.3, 0.6, 0.8, 1.4  # [s] the scripted normal force: on, off, on again


def pressing(t: float) -> bool:
    return CONTACT <= t < LOST or t >= AGAIN


def test_the_first_contact_is_kept_when_contact_returns():
    """A 5 N normal force from 0.3 s, below the threshold from 0.6 s (contact lost 50 ms
    later), back from 0.8 s: the circle started 0.3 s (its delay) after the first contact,
    and after contact returns it goes on where it was. Tick by tick the plain reference
    equals SurfaceReferenceSystem in a Simulator to 1e-12 (x_d, its derivatives, f_d, the
    contact flag), and the tangential reference moves at most speed × T a period (no jump
    back to the circle's start at 0.8 s). Catches the first contact's time replaced by the
    latest contact's (the circle restarts at each new contact)."""
    path = CircleOnSurface(**PANDA_CIRCLE)
    settings = dict(reference=path, task_rows=np.array([0, 1, 2]), contact_threshold=THRESHOLD, period=PERIOD)
    system, plain = SurfaceReferenceSystem(**settings), PlainSurfaceReference(**settings)
    simulator = Simulator(system)
    context = simulator.get_mutable_context()
    port = system.GetInputPort("measured_wrench")
    flags, x_d = [], []
    for k in range(round(END / PERIOD) + 1):
        t = k * PERIOD
        wrench = np.zeros(6)
        wrench[3:] = (5.0 if pressing(t) else 0.1) * path.normal  # f_n = n · f
        port.FixValue(context, wrench)
        if k == 0:
            simulator.Initialize()
        else:
            simulator.AdvanceTo(t)
        expected = system.get_output_port().Eval(context)
        got = plain.tick(t, wrench)
        flat = np.concatenate([got[0], got[1], got[2], [got[3], float(plain.in_contact)]])
        np.testing.assert_allclose(flat, expected, rtol=0, atol=1e-12, err_msg=f"t = {t:.3f} s")
        flags.append(plain.in_contact)
        x_d.append(got[0])
    flags = np.array(flags)
    assert flags[round(0.5 / PERIOD)] and not flags[round(0.7 / PERIOD)] and flags[-1]  # on, lost, on again
    assert plain.state.t_contact == pytest.approx(AGAIN, abs=2 * PERIOD)
    tangential = np.array(x_d) - np.outer(np.array(x_d) @ path.normal, path.normal)
    moved = np.linalg.norm(np.diff(tangential, axis=0), axis=1)
    assert moved.max() <= abs(path.speed) * PERIOD * (1 + 1e-9)
    # the circle has been running since the first contact + delay: at the end it has gone
    # farther than it could have since the second contact
    since_again = END - AGAIN - PANDA_CIRCLE["delay"]
    assert moved.sum() > abs(path.speed) * max(since_again, 0.0) + 0.1 * abs(path.speed)
