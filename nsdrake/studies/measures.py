"""Figures for the realism ladder and the gradient-projection family, from traces alone.

- :func:`force_oscillation`: how the normal force oscillates around the desired one
  once in contact (dominant frequency, RMS and peak-to-peak of the error's part
  faster than 5 Hz, by a Butterworth high-pass),
  the figures of the paper's "rather noisy and oscillates around the desired force".
- :func:`wrong_way_share`: in how many control periods a criterion moved against
  the sign of its gain while it was the active level-2 criterion (Section 3.4's claim
  that Eq. 30's step improves the criterion and Eq. 28's step with J̄ need not).
- :func:`commanded_step_rates`: Φᵀ q̇_dⁿ per period, the first-order change of the
  criterion that the commanded null-space velocity alone would cause (the part the
  paper's claim is about, without the task motion's own effect on the criterion).
"""

from __future__ import annotations

import math

import numpy as np

from nsdrake.control.criteria.joint_torque import joint_torque_criterion
from nsdrake.control.criteria.manipulability import manipulability
from nsdrake.control.dynamics import ArmModel
from nsdrake.experiment.traces import Traces

OSCILLATION_CUTOFF = 5.0  # [Hz] slower changes of the force error count as drift, not oscillation
# An oscillation whose RMS is below this share of the desired force is below the noise floor:
# it has no frequency (0.01 N for fig3's 10 N; the clean run's part above 5 Hz is 6e-6 N, numerical
# ripple, the friction rung's 0.001 N, while the sensor noise leaves 0.07 N and the belts 0.2 N) [-].
OSCILLATION_FLOOR_SHARE = 1e-3
# Modes of Fig. 1 (nsdrake.control.priority.Mode) and the trace column of their criterion.
MODE_CRITERION = {1: "p_obstacle", 2: "p_tau", 3: "w"}
MODE_NAME = {1: "obstacle", 2: "joint_torque", 3: "manipulability"}


def force_oscillation(
    t: np.ndarray, error: np.ndarray, cutoff: float = OSCILLATION_CUTOFF, floor: float = 0.0
):
    """(frequency [Hz], RMS, peak-to-peak) of the oscillating part of a force error e(t)
    sampled at regular times ``t``: e through a zero-phase 4th-order Butterworth
    high-pass at ``cutoff`` (drift slower than that removed). The frequency is the
    largest peak of that part's Hann-windowed amplitude spectrum at or above
    ``cutoff``, nan where the part's RMS is below ``floor`` [N] (the strongest bin of
    a ripple at the noise floor is no oscillation's frequency: with nothing there it
    is the first bin above the cutoff). All nan for fewer than 32 samples."""
    from scipy.signal import butter, sosfiltfilt

    t = np.asarray(t, dtype=float)
    e = np.asarray(error, dtype=float)
    if len(e) < 32:
        return math.nan, math.nan, math.nan
    dt = float(np.median(np.diff(t)))
    sos = butter(4, cutoff, btype="highpass", fs=1.0 / dt, output="sos")
    fast = sosfiltfilt(sos, e - e.mean())
    spectrum = np.abs(np.fft.rfft(fast * np.hanning(len(fast))))
    frequencies = np.fft.rfftfreq(len(fast), dt)
    band = frequencies >= cutoff
    rms = float(np.sqrt(np.mean(fast**2)))
    frequency = float(frequencies[band][np.argmax(spectrum[band])]) if rms >= floor else math.nan
    return frequency, rms, float(np.ptp(fast))


def drift_rate(t: np.ndarray, values: np.ndarray) -> float:
    """The slope of the least-squares line through ``values`` over ``t`` [unit/s]."""
    return float(np.polyfit(np.asarray(t, dtype=float) - t[0], np.asarray(values, dtype=float), 1)[0])


def wrong_way_share(
    values: np.ndarray, gain_sign: float, active: np.ndarray, tolerance: float = 0.0
) -> tuple[float, int]:
    """(share, periods): of the control periods k → k+1 in which ``active[k]``, the
    share whose change values[k+1] − values[k] has the sign opposite to the gain's
    (and exceeds ``tolerance`` in size), and how many periods were active."""
    change = np.diff(np.asarray(values, dtype=float))
    mask = np.asarray(active, dtype=bool)[:-1]
    periods = int(mask.sum())
    if periods == 0:
        return math.nan, 0
    wrong = (np.sign(change) == -np.sign(gain_sign)) & (np.abs(change) > tolerance)
    return float(np.sum(wrong & mask)) / periods, periods


def commanded_step_rates(traces: Traces, arm: ArmModel, mode: int, F_d: np.ndarray) -> np.ndarray:
    """Φ(q)ᵀ q̇_dⁿ per row for the criterion of ``mode`` (2 joint torque, 3
    manipulability), Φ recomputed from the logged q on ``arm`` [criterion unit / s]."""
    context = arm.plant.CreateDefaultContext()
    q, qns = traces.block("q"), traces.block("qns")
    out = np.empty(len(traces))
    zero = np.zeros(arm.n)
    for k in range(len(traces)):
        terms = arm.terms(context, q[k], zero, coriolis=False)
        if mode == 2:
            _, Phi = joint_torque_criterion(terms.J, terms.dJ_dq, F_d)
        elif mode == 3:
            _, Phi = manipulability(terms.J, terms.dJ_dq)
        else:
            raise ValueError(f"no recomputed gradient for mode {mode}")
        out[k] = Phi @ qns[k]
    return out
