"""Closed-loop behaviour of the null-space controller in free motion (Eqs. 23–24)."""

from __future__ import annotations

import numpy as np
from conftest import fig3_with

from nsdrake.experiment.simulate import run

# The plate is moved out of reach and the task reference is still: free motion
# with a fixed tool. The arm starts with a pure self-motion velocity (J q̇ = 0,
# computed below), so eⁿ(0) = −q̇(0) with q̇_dⁿ = 0.
FREE_MOTION = """
duration: {duration}
control_period: 0.001
plate: {{position: [0.0, 5.0, 0.0]}}
reference: {{tangent_speed: 0.0, approach_speed: 1.0e-9}}
desired_null_space:
  criteria: {{obstacle: {{gain: 0.0}}, joint_torque: {{gain: 0.0}}, manipulability: {{gain: 0.0}}}}
report: {{compare_without_null_space_task: false}}
null_space: {{K_n: {K_n}, coriolis_compensation: {coriolis}, task_velocity_compensation: {tvc}}}
arm:
  initial_velocities: {{joint1: {v[0]}, joint2: {v[1]}, joint3: {v[2]}, joint4: {v[3]}}}
"""


def self_motion_velocity(speed: float) -> np.ndarray:
    """A joint velocity at fig3's initial pose with J q̇ = 0 and ‖q̇‖ = speed."""
    from conftest import paper_arm, terms_at

    from nsdrake.experiment.scenario import load_scenario

    s = load_scenario("fig3")
    arm = paper_arm()
    q0 = np.array([s.arm.initial_positions[j] for j in arm.joint_names])
    T = terms_at(arm, q0, np.zeros(4), coriolis=False)
    _, _, Vt = np.linalg.svd(T.J)
    v = Vt[-1]  # spans part of the null space of J
    return speed * v / np.linalg.norm(v)


def free_motion(tmp_path, K_n, coriolis, tvc=True, speed=1.0, duration=0.5):
    v = self_motion_velocity(speed)
    text = FREE_MOTION.format(
        duration=duration, K_n=K_n, coriolis=str(coriolis).lower(), tvc=str(tvc).lower(), v=v
    )
    traces, _ = run(fig3_with(tmp_path, text))
    return traces


def test_null_space_error_decays_and_nu_never_increases(tmp_path):
    """Full compensation: ν = ½ eⁿᵀ H eⁿ decreases at every control period.

    In exact arithmetic ν_{k+1} < ν_k. The discrete plant and sampled controller add
    O(h²) terms proportional to ν itself (everything here scales with eⁿ), so the
    sequence stays monotone; an increase above 1e-12 ν(0) would be a real one.
    """
    traces = free_motion(tmp_path, K_n=10.0, coriolis=True)
    nu, en = traces["nu"], np.linalg.norm(traces.block("en"), axis=1)
    assert nu[0] > 1e-3
    assert np.max(np.diff(nu)) <= 1e-12 * nu[0]
    assert en[-1] < 0.02 * en[0]  # e^{-K_n t}: e^{-5} ≈ 0.007 after 0.5 s


def test_nu_decreases_where_only_the_coriolis_compensation_keeps_it_down(tmp_path):
    """At K_n = 0.2 with a fast self-motion, ½ eᵀḢe outweighs K_n eᵀHe (next test): only
    the H⁻¹ C eⁿ term of Eq. 21 keeps ν̇ = −K_n eᵀHe < 0 (Eq. 24). With the full law ν
    falls at every period; a controller that drops or mis-signs that term fails here."""
    traces = free_motion(tmp_path, K_n=0.2, coriolis=True, speed=-3.0, duration=0.3)
    nu = traces["nu"]
    assert nu[0] > 1e-2
    assert np.max(np.diff(nu)) < 0.0


def test_without_coriolis_compensation_nu_can_increase(tmp_path):
    """The same run without H⁻¹ C eⁿ: then ν̇ = −K_n eᵀHe + ½ eᵀḢe, and at fig3's start
    pose with this self-motion ½ eᵀḢe ≈ 0.42 eᵀHe > K_n eᵀHe (K_n = 0.2): ν rises.
    So the previous test can fail, and Eq. 24 does need the compensation."""
    traces = free_motion(tmp_path, K_n=0.2, coriolis=False, speed=-3.0, duration=0.3)
    nu = traces["nu"]
    assert np.max(np.diff(nu)) > 1e-6 * nu[0]
