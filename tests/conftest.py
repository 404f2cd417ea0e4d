"""Shared fixtures: the paper's arm, test arms of other shapes, and seeded states."""

from __future__ import annotations

import os
import sys
import tempfile
from pathlib import Path

import numpy as np
import pytest
from pydrake.multibody.parsing import Parser
from pydrake.multibody.plant import MultibodyPlant

from nsdrake.control.dynamics import ArmModel
from nsdrake.station.models import models_dir

# The convex hulls nsdrake keeps for vendors' STL/DAE meshes: in a folder of the tests' own,
# not the user's ~/.cache (child processes inherit it).
os.environ.setdefault("NSDRAKE_CACHE", str(Path(tempfile.gettempdir()) / "nsdrake-tests-cache"))

sys.path.insert(0, str(Path(__file__).parent))
from models import TEST_ARMS  # noqa: E402


def arm_from_urdf_text(text: str, axes) -> ArmModel:
    plant = MultibodyPlant(0.0)
    Parser(plant).AddModelsFromString(text, "urdf")
    plant.Finalize()
    return ArmModel(plant, plant.GetFrameByName("tool"), axes)


def paper_arm() -> ArmModel:
    plant = MultibodyPlant(0.0)
    Parser(plant).AddModels(str(models_dir() / "arm4.urdf"))
    plant.Finalize()
    return ArmModel(plant, plant.GetFrameByName("tool"), ("x", "y"))


PANDA_POSE_AXES = ("x", "y", "z", "rx", "ry", "rz")
# urdf/README's table-wiping start: tool 0.5 m in front of the base, 0.15 m high, pointing down.
PANDA_Q0 = np.array([0.0, 0.182, 0.0, -2.400, 0.0, 2.582, 0.785])


def panda_arm(axes=PANDA_POSE_AXES) -> ArmModel:
    """urdf/panda.urdf alone in a continuous plant, with ``axes`` as task axes."""
    plant = MultibodyPlant(0.0)
    Parser(plant).AddModels(str(models_dir() / "panda.urdf"))
    plant.Finalize()
    return ArmModel(plant, plant.GetFrameByName("tool"), axes)


def panda_configurations(count: int, seed: int, near_singular: int = 0) -> list[np.ndarray]:
    """``count`` seeded q uniform within the Panda's joint limits, then ``near_singular``
    more within 1e-3 rad (offsets 5e-4…1e-3 rad per joint, random signs) of poses where
    the 6 × 7 pose Jacobian loses rank (:func:`panda_singular_poses`)."""
    rng = np.random.default_rng(seed)
    plant = panda_arm().plant
    lo, hi = plant.GetPositionLowerLimits(), plant.GetPositionUpperLimits()
    out = [rng.uniform(lo, hi) for _ in range(count)]
    singular = panda_singular_poses(max(1, min(near_singular, 4)), seed)
    for k in range(near_singular):
        offset = rng.choice([-1.0, 1.0], 7) * rng.uniform(5e-4, 1e-3, 7)
        out.append(singular[k % len(singular)] + offset)
    return out


def panda_singular_poses(count: int, seed: int) -> list[np.ndarray]:
    """``count`` poses within the Panda's limits where the pose Jacobian's smallest
    singular value is below 1e-8 (from ~0.1 elsewhere): σ_min² minimised from seeded
    random starts. (The 6 × 7 Jacobian loses rank on a set of codimension 2, e.g.
    q2 = 0, which lines joint 3 up with joint 1, together with one more condition;
    a search finds such poses without listing the conditions.)"""
    from scipy.optimize import minimize

    arm = panda_arm()
    context = arm.plant.CreateDefaultContext()
    lo, hi = arm.plant.GetPositionLowerLimits(), arm.plant.GetPositionUpperLimits()
    zero = np.zeros(7)
    rng = np.random.default_rng(seed)

    def sigma_min(q):
        return np.linalg.svd(arm.terms(context, q, zero, False).J, compute_uv=False)[-1]

    out = []
    while len(out) < count:
        result = minimize(
            lambda q: sigma_min(q) ** 2,
            rng.uniform(lo + 0.2, hi - 0.2),
            method="L-BFGS-B",
            bounds=list(zip(lo + 0.05, hi - 0.05, strict=True)),
            options={"ftol": 1e-30, "gtol": 1e-14, "maxiter": 2000},
        )
        if sigma_min(result.x) < 1e-8:
            out.append(result.x)
    return out


ARM_NAMES = ["arm4", *TEST_ARMS]


def make_arm(name: str) -> ArmModel:
    if name == "arm4":
        return paper_arm()
    text, axes = TEST_ARMS[name]
    return arm_from_urdf_text(text, axes)


@pytest.fixture(params=ARM_NAMES)
def arm(request) -> ArmModel:
    """Every test arm in turn: the paper's 4-DOF planar arm and arms of other shapes."""
    return make_arm(request.param)


@pytest.fixture
def arm4() -> ArmModel:
    return paper_arm()


def terms_at(arm: ArmModel, q, v, coriolis=True):
    return arm.terms(arm.plant.CreateDefaultContext(), np.asarray(q, float), np.asarray(v, float), coriolis)


def fig3_with(tmp_path, overrides: str = "", duration: float | None = None):
    """The shipped fig3 scenario with a YAML overlay (written to a file, as a user would)."""
    from nsdrake.experiment.scenario import load_scenario

    if not overrides:
        return load_scenario("fig3", duration=duration)
    path = tmp_path / "overrides.yaml"
    path.write_text(overrides)
    return load_scenario("fig3", config=path, duration=duration)


def simulate_to(scenario, t_end: float):
    """Builds the diagram, simulates to ``t_end`` and returns (built, root context)."""
    from pydrake.systems.analysis import Simulator

    from nsdrake.experiment.diagram import build_diagram

    built = build_diagram(scenario)
    simulator = Simulator(built.diagram)
    context = simulator.get_mutable_context()
    plant = built.station.plant
    plant_context = plant.GetMyMutableContextFromRoot(context)
    plant.SetPositions(plant_context, built.station.q0)
    plant.SetVelocities(plant_context, built.station.v0)
    simulator.Initialize()
    simulator.AdvanceTo(t_end)
    return built, context


# A short fig3 run into a folder, shared by the visualization, report and browser tests:
# contact comes at ≈ 1.27 s, so at 2 s the tool presses on the plate.
SHORT_RUN_DURATION = 2.0


def once_per_test_run(tmp_path_factory, name: str, compute):
    """``compute(folder)``'s value, computed once in the whole pytest run and read back
    (pickled) by every other worker: the xdist workers of one run share the parent of their
    base temporary folders, and a lock file there makes the first worker compute while the
    others wait (pytest-xdist's documented way to run a session fixture once; xdist's
    ``--dist loadgroup`` cannot keep tests together under pytest 9). Without xdist: computed
    here. ``folder`` holds what the computation writes; the value must pickle."""
    import fcntl
    import os
    import pickle
    import shutil

    root = tmp_path_factory.getbasetemp()
    if os.environ.get("PYTEST_XDIST_WORKER"):
        root = root.parent
    folder = root / f"shared-{name}"
    with open(root / f"shared-{name}.lock", "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        done = folder / "value.pickle"
        if not done.exists():
            shutil.rmtree(folder, ignore_errors=True)  # what a worker that failed here left
            folder.mkdir()
            value = compute(folder)
            partial = folder / "value.pickle.partial"
            partial.write_bytes(pickle.dumps(value))
            partial.replace(done)
        return pickle.loads(done.read_bytes())


@pytest.fixture(scope="session")
def short_run(tmp_path_factory):
    """(out folder, RunResult) of ``run_to_folder`` on fig3 for 2 s: simulated once in the
    whole test run (:func:`once_per_test_run`). Tests read the folder, never change it."""
    from nsdrake.experiment.scenario import load_scenario
    from nsdrake.reporting.run_folder import run_to_folder

    def compute(folder):
        out = folder / "fig3_short"
        out.mkdir()  # run_to_folder writes into a folder that is ready
        return out, run_to_folder(load_scenario("fig3", duration=SHORT_RUN_DURATION), out)

    return once_per_test_run(tmp_path_factory, "fig3_short", compute)


def without_notices(err: str) -> str:
    """stderr without what a command prints besides its messages: the one-time compile
    notice of nsdrake's kernels (a fresh install compiles them in whichever process runs
    first) and progress lines (one every LOG_INTERVAL of wall time when not on a terminal)."""
    import re

    from nsdrake.control.kernels import NOTICE

    err = err.replace(NOTICE + "\n", "")
    return re.sub(r"(?m)^[^:\n]+: (\d+%|\d+/\d+ \w+)( \(\d+ failed\))?, [^\n]*\d+ s[^\n]*\n", "", err)


def shipped_run(tmp_path_factory, name: str):
    """(traces, built) of the shipped scenario ``name`` simulated directly for its whole
    duration (``run(load_scenario(name))``), once in the whole test run
    (:func:`once_per_test_run`: the traces; ``built`` is the same scenario's diagram built
    again in this worker, unsimulated, for its station). Read them, never change them."""
    from nsdrake.experiment.diagram import build_diagram
    from nsdrake.experiment.scenario import load_scenario
    from nsdrake.experiment.simulate import run

    scenario = load_scenario(name)
    traces = once_per_test_run(tmp_path_factory, f"shipped-{name}", lambda folder: run(scenario)[0])
    return traces, build_diagram(scenario)


@pytest.fixture(scope="session")
def panda_wipe_direct(tmp_path_factory):
    """:func:`shipped_run` of panda_wipe (28 s): the acceptance figures
    (experiment/test_panda_scenarios.py), the drive's comparison with the direct run
    (driver/test_drive_reproduces.py) and the torque rate the law asks for at first contact
    (experiment/test_first_contact.py) read the same run."""
    return shipped_run(tmp_path_factory, "panda_wipe")


@pytest.fixture(scope="session")
def finished_run(tmp_path_factory) -> Path:
    """A finished ``nsdrake run fig3 --duration 0.1`` (with its replay), in process, once in
    the whole test run (:func:`once_per_test_run`): the earlier run's folder that the
    --overwrite tests start from. Tests take a copy (:func:`copy_of_finished_run`), never
    this folder."""
    import contextlib
    import io

    from nsdrake.cli import main

    def compute(folder):
        out = folder / "run"
        with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(io.StringIO()):
            assert main(["run", "fig3", "--duration", "0.1", "--out", str(out)]) in (0, 1)  # before contact
        return out

    return once_per_test_run(tmp_path_factory, "finished_run", compute)


def copy_of_finished_run(finished: Path, destination: Path) -> Path:
    """A copy of :func:`finished_run`'s folder at ``destination`` (which must not exist):
    byte for byte the folder that run would have written there (its manifest names files
    relative to the folder)."""
    import shutil

    shutil.copytree(finished, destination)
    return destination
