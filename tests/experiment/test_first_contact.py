"""The first contact within Franka's torque rate (issue 35, item 4): the guarded approach
(the speed falls to ``touch_speed`` before the surface), the normal reference's stop at
contact over ``stop_time``, the metrics that report the transition (the force's peak, the
time off the surface), and (slow) every shipped Panda scenario asking for less than
1000 N m/s on every joint, computed from its traces with the rate limit off.

The profiles are checked against what nsdrake did not write: SciPy's quadrature of the
speed, its root finder for where the approach reaches the slow-down distance, and finite
differences.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
import yaml
from scipy.integrate import quad
from scipy.optimize import brentq

from nsdrake.experiment.reference import (
    ContactState,
    PlainSurfaceReference,
    SlideAndPress,
    TaskReferenceError,
    approach_profile,
    ramp_profile,
    stop_profile,
)
from nsdrake.experiment.scenario import ScenarioError, load_scenario
from nsdrake.experiment.traces import Traces
from nsdrake.reporting.metrics import first_contact_metrics, limit_metrics

SCENARIOS = Path(__file__).resolve().parents[2] / "nsdrake" / "experiment" / "scenarios"
FRANKA_RATE = 1000.0  # [N m/s] Franka's published torque-rate limit, every joint
GUARDED = {"approach_speed": 0.025, "touch_speed": 0.003, "slow_down_distance": 0.014, "stop_time": 0.1}


def panda_scenarios() -> list[str]:
    """Every shipped scenario on the Panda (its arm's URDF is panda.urdf)."""
    names = []
    for path in sorted(SCENARIOS.glob("*.yaml")):
        arm = (yaml.safe_load(path.read_text()) or {}).get("arm", {})
        if arm.get("urdf") == "panda.urdf":
            names.append(path.stem)
    return names


def press(**overrides) -> SlideAndPress:
    base = dict(
        x0=np.array([0.5, 0.0, 0.15]),
        tangent=np.zeros(3),
        normal=np.array([0.0, 0.0, -1.0]),
        tangent_speed=0.0,
        blend_time=0.5,
        force=10.0,
        force_ramp_time=0.3,
        **GUARDED,
    )
    return SlideAndPress(**(base | overrides))


# ---------------------------------------------------------------- the profiles


def test_the_guarded_approach_has_slowed_to_the_touch_speed_at_the_slow_down_distance():
    """r(t) is the integral of ṙ (SciPy's quadrature), r̈ the derivative of ṙ (central
    differences), ṙ rises from rest to approach_speed and falls to touch_speed, and where r
    reaches slow_down_distance (SciPy's root finder) ṙ is touch_speed and stays there.
    Catches a slow-down started blend_time / 2 early or late (the speed reaches touch_speed
    elsewhere than at the distance), a fall of the whole speed instead of speed − touch_speed
    (the approach stops short of the surface), a dropped r̈ of the fall."""
    v, v_t, b, d = GUARDED["approach_speed"], GUARDED["touch_speed"], 0.5, GUARDED["slow_down_distance"]

    def profile(t):
        return approach_profile(t, v, b, v_t, d)

    t_s = 0.5 * b + (d - 0.5 * (v + v_t) * b) / v  # where the fall starts: only a hint to SciPy
    for t in np.linspace(0.0, 2.5, 51):
        kinks = [p for p in (b, t_s, t_s + b) if 0.0 < p < t]
        integral, _ = quad(lambda s: profile(s)[1], 0.0, t, limit=200, points=kinks or None)
        assert profile(t)[0] == pytest.approx(integral, abs=1e-11)
        h = 1e-6
        if t > h:
            assert (profile(t + h)[1] - profile(t - h)[1]) / (2 * h) == pytest.approx(profile(t)[2], abs=1e-6)
    at_distance = brentq(lambda t: profile(t)[0] - d, 0.0, 5.0, xtol=1e-14)
    assert profile(at_distance)[1] == pytest.approx(v_t, abs=1e-9)
    assert profile(at_distance - 0.01)[1] > v_t + 1e-6  # still slowing just before
    speeds = [profile(t)[1] for t in np.linspace(at_distance, at_distance + 3.0, 31)]
    assert np.allclose(speeds, v_t, rtol=0, atol=1e-15)
    assert max(profile(t)[1] for t in np.linspace(0, at_distance, 500)) == pytest.approx(v, abs=1e-12)


def test_without_a_touch_speed_the_approach_is_the_ramp():
    """touch_speed 0 (every scenario but the Panda's, fig3 among them) leaves the approach
    exactly the old ramp, and stop_time 0 the old stop at contact: x_d frozen where
    contact was detected, at rest. Catches a change of fig3's reference."""
    old = press(touch_speed=0.0, slow_down_distance=0.0, stop_time=0.0, approach_speed=0.03)
    state = ContactState(t_contact=1.2, r_contact=0.0301)
    for t in np.linspace(0.0, 1.19, 60):
        assert approach_profile(t, 0.03, 0.5, 0.0, 0.0) == ramp_profile(t, 0.03, 0.5)
    for t in (1.2, 1.25, 3.0):
        x_d, xdot_d, xddot_d, _ = old.at(t, state=state)
        assert (x_d - old.x0) @ old.normal == pytest.approx(0.0301, abs=1e-15)
        assert not xdot_d.any() and not xddot_d.any()
    fig3 = load_scenario("fig3").reference
    assert (fig3.touch_speed, fig3.slow_down_distance, fig3.stop_time) == (0.0, 0.0, 0.0)


def test_at_contact_the_reference_comes_to_rest_from_its_speed():
    """Contact at t_c: ẋ_d's normal part goes on from the speed it had (no step), falls to 0
    over stop_time with r̈ its derivative, and x_d rests touch_speed · stop_time / 2 beyond
    where contact was detected (SciPy's quadrature of the speed). Catches the old stop (ẋ_d
    from touch_speed to 0 in one period: the step the normal damping turned into
    12.8 kN m/s), a stop that starts from the approach's full speed, or one that ends
    elsewhere than its integral."""
    ref = press()
    t_c, r_c = 2.0, 0.0146
    state = ContactState(t_contact=t_c, r_contact=r_c, v_contact=0.003)

    def normal(t):
        x_d, xdot_d, xddot_d, _ = ref.at(t, state=state)
        return (x_d - ref.x0) @ ref.normal, xdot_d @ ref.normal, xddot_d @ ref.normal

    assert normal(t_c)[:2] == pytest.approx((r_c, 0.003), abs=1e-15)
    assert normal(t_c - 1e-9)[1] == pytest.approx(0.003, abs=1e-12)  # the approach's, just before
    for t in np.linspace(t_c + 0.001, t_c + 0.099, 25):
        h = 1e-6
        assert (normal(t + h)[1] - normal(t - h)[1]) / (2 * h) == pytest.approx(normal(t)[2], abs=1e-6)
    travel, _ = quad(lambda t: normal(t)[1], t_c, t_c + 0.2)
    assert normal(t_c + 0.5)[0] - r_c == pytest.approx(travel, abs=1e-12)
    assert travel == pytest.approx(0.003 * 0.1 / 2, rel=1e-9)
    assert normal(t_c + 0.1)[1:] == (0.0, 0.0)
    assert stop_profile(0.05, 0.003, 0.0) == (0.0, 0.0, 0.0)


def test_the_drive_loop_carries_the_speed_at_contact():
    """PlainSurfaceReference (nsdrake drive's reference) ticked every 1 ms with the force
    reaching the threshold at t = 1.6 s: the normal speed of x_d changes by no more than
    its largest acceleration allows in one period (75 µm/s in the approach's rise, 45 µm/s
    in the stop; a stop at once steps by the 3 mm/s touch speed), and after a contact lost
    and regained the reference stops from the re-approach's speed, not from the first
    approach's. Catches the contact's speed not
    kept by update_contact (the re-contact's stop then starts from the wrong speed)."""
    ref = press()
    plain = PlainSurfaceReference(
        reference=ref, task_rows=np.array([0, 1, 2]), contact_threshold=0.5, period=0.001
    )

    def wrench(f):
        return np.array([0.0, 0.0, 0.0, 0.0, 0.0, -f])  # the tool pushes down (normal −z)

    speeds = []
    for k in range(2400):
        t = k * 0.001
        force = 1.0 if 1.6 <= t < 2.0 or t >= 2.2 else 0.0
        speeds.append(plain.tick(t, wrench(force))[1] @ ref.normal)
    speeds = np.array(speeds)
    steps = np.abs(np.diff(speeds[:2000]))
    assert plain.state.in_contact and plain.state.t_contact > 2.0  # lost at ~2.05, regained
    assert steps.max() < 8e-5 and steps[1590:1700].max() < 5e-5
    first = plain.first
    assert first == pytest.approx(1.599)  # the update at the previous tick sees the measurement
    regained = plain.state
    assert regained.v_contact == pytest.approx(speeds[int(round(regained.t_contact / 0.001))], abs=1e-12)
    approach = approach_profile(regained.t_contact, 0.025, 0.5, 0.003, 0.014)
    assert regained.v_contact < 0.5 * approach[1]  # the re-approach's, from rest, not the touch speed


# ---------------------------------------------------------------- refused settings


@pytest.mark.parametrize(
    "overrides, field, words",
    [
        ({"touch_speed": 0.03}, "touch_speed", "must be below approach_speed"),
        ({"slow_down_distance": 0.005}, "slow_down_distance", "must be at least 0.01325 m"),
        ({"touch_speed": 0.0}, "slow_down_distance", "needs a touch_speed > 0"),
        ({"stop_time": -0.1}, "stop_time", ""),
        ({"touch_speed": math.nan}, "touch_speed", ""),
    ],
)
def test_a_guarded_approach_it_cannot_follow_is_refused(tmp_path, overrides, field, words):
    """A touch speed not below the approach's (the approach would speed up to touch), a
    slow-down distance shorter than the rise and fall of the speed, a slow-down distance
    without a touch speed (a setting that does nothing), a negative stop time: refused in
    one line naming the field, by the path and by the scenario before anything is built."""
    with pytest.raises(TaskReferenceError, match=f"SlideAndPress.{field}: .*{words}"):
        press(**overrides)
    path = tmp_path / "guarded.yaml"
    path.write_text(yaml.safe_dump({"reference": {k: float(v) for k, v in (GUARDED | overrides).items()}}))
    with pytest.raises(ScenarioError, match=f"reference.{field}: .*{words}") as error:
        load_scenario("panda_wipe", config=path)
    assert "\n" not in str(error.value)


def test_the_shortest_slow_down_distance_is_refused_below_and_taken_at_and_above(tmp_path):
    """The bound on slow_down_distance, approach_speed × blend_time + touch_speed ×
    blend_time / 2 (13.25 mm for the Panda's guarded approach), from both sides: at it and
    above it the path is built (SlideAndPress) and the scenario loads, and the speed
    profile reaches approach_speed (the rise ends before the fall starts: the bound's
    meaning, checked on the profile itself); just below it (1e-9 relative) and halfway
    down to approach_speed × blend_time (13.125 mm) refused by both, and there the speed
    never reaches approach_speed. Catches the bound without its touch-speed term (13.125 mm
    taken: an approach that never reaches its speed), or compared the other way at the
    bound (the bound itself refused): issue 46, mistake 11."""
    v, v_t, b = GUARDED["approach_speed"], GUARDED["touch_speed"], 0.5
    bound = v * b + 0.5 * v_t * b
    assert bound == pytest.approx(0.01325, abs=1e-15)
    times = np.append(np.linspace(0.0, 3.0, 3001), b)  # the peak at the bound is at t = blend_time

    def peak_speed(d):
        return max(approach_profile(t, v, b, v_t, d)[1] for t in times)

    cases = [(bound, True), (bound * (1 + 1e-9), True), (0.02, True)]
    cases += [(bound * (1 - 1e-9), False), (0.5 * (bound + v * b), False)]
    assert peak_speed(0.5 * (bound + v * b)) < v - 1e-5  # well short of the approach speed there
    for d, taken in cases:
        config = tmp_path / "guarded.yaml"
        config.write_text(yaml.safe_dump({"reference": {**GUARDED, "slow_down_distance": float(d)}}))
        if taken:
            assert peak_speed(d) == pytest.approx(v, abs=1e-12), d
            press(slow_down_distance=d)
            load_scenario("panda_wipe", config=config)
        else:
            words = "slow_down_distance: must be at least 0.01325 m"
            with pytest.raises(TaskReferenceError, match=words):
                press(slow_down_distance=d)
            with pytest.raises(ScenarioError, match=f"reference.{words}"):
                load_scenario("panda_wipe", config=config)


# ---------------------------------------------------------------- the metrics


def contact_traces(bounce_rows: int = 0, peak: float = 10.0, peak_at: float = 1.4) -> Traces:
    """1 kHz traces: contact at 1.0 s, f_d ramps to 10 N; ``bounce_rows`` rows of f_n = 0
    from 1.010 s (the tool off the table), a force ``peak`` at ``peak_at``."""
    t = np.round(np.arange(0.0, 3.0, 0.001), 9)
    f_d = np.clip((t - 1.0) / 0.3, 0.0, 1.0) * 10.0
    f_n = np.where(t >= 1.0, np.maximum(f_d, 0.6), 0.0)
    f_n[(t >= 1.010) & (t < 1.010 + bounce_rows * 0.001 - 1e-9)] = 0.0
    f_n[np.argmin(np.abs(t - peak_at))] = peak
    return Traces({"t": t, "f_n": f_n, "f_d": f_d})


def test_the_first_contact_metrics_report_a_bounce_and_an_overshoot():
    """time_off_surface counts the rows with f_n ≤ 0 after first contact (35 rows: 35 ms,
    the old panda_wipe's) and fails any; contact_force_peak is the largest f_n in the
    settling half-second and fails above f_d + 10%. The rows before contact do not count.
    Catches a time off counted from t = 0 (the approach), a peak taken over the window the
    force figures already cover, or a bound on the wrong side."""
    good = {m.name: m for m in first_contact_metrics(contact_traces(), 0.5)}
    assert good["time_off_surface"].value == 0.0 and good["time_off_surface"].passed
    assert good["contact_force_peak"].value == pytest.approx(10.0) and good["contact_force_peak"].passed
    bounced = {m.name: m for m in first_contact_metrics(contact_traces(bounce_rows=35), 0.5)}
    assert bounced["time_off_surface"].value == pytest.approx(0.035)
    assert bounced["time_off_surface"].passed is False
    over = {m.name: m for m in first_contact_metrics(contact_traces(peak=11.5), 0.5)}
    assert over["contact_force_peak"].value == 11.5 and over["contact_force_peak"].passed is False
    late = contact_traces(peak=11.5, peak_at=2.0)  # in the window: force_error_max's
    assert {m.name: m.passed for m in first_contact_metrics(late, 0.5)}["contact_force_peak"]


def test_a_clipped_row_fails_the_limits():
    """saturated_joints_max fails when one row had a joint's task torque clipped (the old
    panda_wipe had 19). Catches the figure reported without its bound."""
    k = 100
    columns = {f"{kind}_margin1": np.ones(k) for kind in ("q", "v", "tau")}
    clean = Traces(columns | {"saturated_joints": np.zeros(k)})
    one = np.zeros(k)
    one[50] = 2.0
    assert {m.name: m.passed for m in limit_metrics(clean)}["saturated_joints_max"] is True
    clipped = Traces(columns | {"saturated_joints": one})
    assert {m.name: m.passed for m in limit_metrics(clipped)}["saturated_joints_max"] is False


def test_every_shipped_panda_scenario_approaches_guarded():
    """Every shipped Panda scenario (found by its arm's URDF, so a new one is covered) has a
    guarded approach that has slowed to its touch speed before the table: at most 3 mm/s,
    with a stop at contact. Fast; the closed-loop figures below are the acceptance."""
    names = panda_scenarios()
    assert {"panda_wipe", "panda_self_motion"} <= set(names)
    for name in names:
        r = load_scenario(name).reference
        assert 0.0 < r.touch_speed <= 0.003 and r.stop_time > 0.0, name


# ---------------------------------------------------------------- closed loop (slow)


def rates(traces: Traces) -> np.ndarray:
    """Per joint, the largest |Δτ / Δt| of the commanded torque between rows [N m/s]."""
    tau = traces.block("tau")
    return np.max(np.abs(np.diff(tau, axis=0)) / np.diff(traces["t"])[:, None], axis=0)


@pytest.mark.slow
@pytest.mark.parametrize("name", panda_scenarios())
def test_the_shipped_panda_scenario_asks_for_less_than_franka_torque_rate(name, tmp_path_factory):
    """The whole shipped run asks its actuator limiter for nothing: τ₀ never scaled (s = 1)
    and no joint clipped in any row, so its traces hold what the law asks for, not what the
    limiter let through; every joint's commanded torque changes by less than 1000 N m/s
    between rows (finite differences of the tau columns), the tool never leaves the table
    after it touched it, the force's peak while it settles is within f_d + 10%. On the old
    reference (a stop at once, touching at 13 mm/s) joint 2 asked for 12.8 kN m/s and the
    tool left the table for 17 ms.

    The run is conftest's shipped_run, the one the acceptance figures and the drive's
    comparison read (panda_wipe: 28 s, simulated once in the whole test run). Until
    2026-12-02 this test simulated the run again with the torque-rate limit taken off; while
    the limiter never acts (asserted first) the two runs are one: each tick's τ is
    τ_task + 1·τ₀ inside both windows, so the states, and by induction every later tick,
    are the same (checked bit-identical for both shipped Panda scenarios that day). A law
    asking for more than the rate limit in some row makes the limiter act there: s < 1 or a
    joint clipped, and the first assertion fails."""
    from conftest import shipped_run

    scenario = load_scenario(name)
    traces, _ = shipped_run(tmp_path_factory, name)
    acted = np.flatnonzero((traces["tau0_scale"] != 1.0) | (traces["saturated_joints"] != 0))
    assert acted.size == 0, f"the limiter acted in {acted.size} rows, first at t = {traces['t'][acted[0]]} s"
    asked = rates(traces)
    assert np.all(asked < FRANKA_RATE), dict(enumerate(np.round(asked, 1), start=1))
    metrics = {m.name: m for m in first_contact_metrics(traces, scenario.reference.contact_threshold)}
    assert metrics["time_off_surface"].passed, metrics["time_off_surface"].value
    assert metrics["contact_force_peak"].passed, metrics["contact_force_peak"].value
