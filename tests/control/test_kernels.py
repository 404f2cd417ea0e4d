"""The compiled kernels' housekeeping (nsdrake.control.kernels): one line while they
compile, and no stale machine code after a callee's source changes."""

from __future__ import annotations

import os
import subprocess
import sys
import tempfile
from pathlib import Path
from types import SimpleNamespace

import pytest
from numba.core import config

from nsdrake.control.kernels import CLAIMS, NOTICE, STAMP, _CompileNotice, cache_folder, refresh_cache

ROOT = Path(__file__).resolve().parents[2]  # the repository: tests.vendor_arm imports from there


def _event(module: str):
    return SimpleNamespace(data={"dispatcher": SimpleNamespace(py_func=SimpleNamespace(__module__=module))})


def test_the_notice_is_one_line_for_the_first_nsdrake_kernel(capsys):
    """Catches a line per kernel (a first run compiles about 170), a line for other
    packages' kernels, and no line at all."""
    notice = _CompileNotice()
    notice.on_start(_event("numba.np.arrayobj"))
    assert capsys.readouterr().err == ""
    for module in ("nsdrake.control.stages", "nsdrake.control.priority", "nsdrake.station.force_sensor"):
        notice.on_start(_event(module))
    assert capsys.readouterr().err == NOTICE + "\n"


def test_a_changed_kernel_source_deletes_the_cached_kernels_once(tmp_path, monkeypatch):
    """Catches a cache kept after a callee's file changed (numba watches only a kernel's
    own file), a cache deleted on every start (each run would compile again), and files
    other than nsdrake's cached kernels deleted."""
    monkeypatch.setattr(config, "CACHE_DIR", "")  # numba's default: __pycache__ beside the source
    package = tmp_path / "nsdrake"
    (package / "control" / "__pycache__").mkdir(parents=True)
    source = package / "control" / "stages.py"
    source.write_text("@njit(cache=True)\ndef f(x):\n    return x\n")
    (package / "control" / "plain.py").write_text("def g():\n    pass\n")
    cached = [package / "control" / "__pycache__" / f"stages.f-2.py311.{k}" for k in ("nbi", "1.nbc")]
    other = package / "control" / "__pycache__" / "stages.cpython-311.pyc"

    def fill():
        for path in (*cached, other):
            path.write_bytes(b"x")

    fill()
    assert refresh_cache(package)  # no stamp yet: compiled by an unknown version
    assert not any(p.exists() for p in cached) and other.exists()
    assert (package / "__pycache__" / STAMP).is_file()
    fill()
    assert not refresh_cache(package)  # unchanged: loads
    assert all(p.exists() for p in cached)
    source.write_text(source.read_text() + "\n# edited\n")
    assert refresh_cache(package)
    assert not any(p.exists() for p in cached) and other.exists()


def test_with_numba_cache_dir_the_stamp_and_the_deletions_are_there(tmp_path, monkeypatch):
    """NUMBA_CACHE_DIR moves numba's cache (a test's cold cache, a read-only install): the
    check must stamp and clean that cache. Catches a stamp written beside the sources by a
    run whose kernels live elsewhere, which vouched for a default cache compiled from older
    sources (they then ran stale), and the moved cache never cleaned."""
    package = tmp_path / "nsdrake"
    (package / "control").mkdir(parents=True)
    (package / "__init__.py").write_text("")
    source = package / "control" / "stages.py"
    source.write_text("@njit(cache=True)\ndef f(x):\n    return x\n")
    monkeypatch.setattr(config, "CACHE_DIR", str(tmp_path / "cache"))
    moved = cache_folder(source)
    moved.mkdir(parents=True)
    cached = moved / "stages.f-2.py311.nbi"
    cached.write_bytes(b"x")
    assert refresh_cache(package) and not cached.exists()
    assert not (package / "__pycache__").exists()  # nothing stamped beside the sources
    cached.write_bytes(b"x")
    assert not refresh_cache(package) and cached.exists()
    source.write_text(source.read_text() + "\n# edited\n")
    assert refresh_cache(package) and not cached.exists()


# Every way a controller is built and run, in a process of its own (the test session's
# other tests call kernels with types of their own): after compile_kernels, building
# and running each must compile nothing. Prints nsdrake's kernels compiled afterwards.
_EVERY_CONFIGURATION = """
import dataclasses, sys
from pathlib import Path
import numpy as np
from numba.core import event
from pydrake.multibody.parsing import Parser
from pydrake.multibody.plant import MultibodyPlant
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder
from nsdrake import ControllerConfig, ControllerModel, ControllerStep
from nsdrake.station.models import models_dir
from nsdrake.control.kernels import compile_kernels
from nsdrake.experiment.diagram import build_controller, build_diagram
from nsdrake.experiment.scenario import load_scenario, shipped_scenarios
from nsdrake.experiment.scenario_station import add_scenario_station

compile_kernels()
compiled = []

class Compiles(event.Listener):
    def on_start(self, ev):
        f = ev.data["dispatcher"].py_func
        if f.__module__.startswith("nsdrake."):
            compiled.append(f"{f.__module__}.{f.__name__}{tuple(ev.data['args'])}")
    def on_end(self, ev):
        pass

event.register("numba:compile", Compiles())

def steps(step, q0, period, m_t, rotational):
    extra = (np.array([0.0, 1.0, 0.0, 0.0]), np.zeros(3), np.zeros(3)) if rotational else ()
    for k in range(3):  # t = 0 as a Python int first, as a user may write it
        step.step(k * period if k else 0, q0, np.zeros_like(q0), np.zeros(6), np.zeros(m_t),
                  np.zeros(m_t), np.zeros(m_t), 5.0, *extra)

for name in shipped_scenarios():
    scenario = load_scenario(name)
    for structure in ("systems", "fused"):
        built = build_diagram(dataclasses.replace(scenario, controller_structure=structure))
        simulator = Simulator(built.diagram)
        simulator.AdvanceTo(3 * scenario.control_period)
    station = add_scenario_station(DiagramBuilder(), scenario)
    c = build_controller(scenario, station, station.sensor.p_WSo)
    step = ControllerStep(
        controller_model=c.model, normal=c.normal, config=c.config, wrench_point=c.wrench_point
    )
    steps(step, station.q0, step.config.period, step.plan.m_t, step.plan.m_r > 0)
# the Panda from a plant of one's own: Drake's terms
plant = MultibodyPlant(0.0)
Parser(plant).AddModels(str(models_dir() / "panda.urdf"))
plant.Finalize()
model = ControllerModel.from_plant(plant, tool_frame="tool", task_axes=("x", "y", "z"))
step = ControllerStep(controller_model=model, normal=[0.0, 0.0, -1.0], config=ControllerConfig())
steps(step, np.array([0.0, 0.3, 0.0, -2.0, 0.0, 2.3, 0.8]), step.config.period, 3, False)
# a vendor's arm with OBJ meshes on its links and a ball obstacle: the obstacle row from
# Drake's queries (issue 42), with Pinocchio's terms and with Drake's, a pose task
import tempfile
from pydrake.geometry import Sphere
from pydrake.math import RigidTransform
from nsdrake.control import Obstacle
from tests.vendor_arm import Q0, write_vendor_arm
arm = write_vendor_arm(Path(tempfile.mkdtemp()))
for dynamics in ("pinocchio", "drake"):
    ball = Obstacle("ball", Sphere(0.03), RigidTransform([0.3, 0.0, 0.9]))
    pose = ("x", "y", "z", "rx", "ry", "rz")
    model = ControllerModel.from_file(arm.urdf, tool_frame="tool", task_axes=pose, obstacles=[ball],
                                      dynamics=dynamics)
    config = ControllerConfig(period=0.001)
    config.desired_null_space.criteria.obstacle.gain = 1.0
    step = ControllerStep(controller_model=model, config=config)
    zero = np.zeros(3)
    for k in range(3):  # no force axis: no wrench, no f_d
        R_d = np.array([1.0, 0, 0, 0])
        step.step(0.001 * k, Q0, np.zeros(7), None, zero, zero, zero, None, R_d, zero, zero)
    model.terms(model.create_scratch(), Q0, np.ones(7), True)  # the model's own RobotTerms
# the selector and the orientation error from Python, as the API calls them (ints where a
# user may write them)
from nsdrake.control.orientation import orientation_error_angle
from nsdrake.control.priority import (Mode, SelectorLimits, SwitchState, blend_weight, select_mode,
                                      update_switch_state)
limits = SelectorLimits(d_lim=1, d_band=0, w_lim=0, w_band=0, q_lim=0, q_band=0)
select_mode(1, 0.5, Mode(0), limits, margin=2)
state = update_switch_state(SwitchState.from_array(np.array([0.0, 0.0, -np.inf])), 1, Mode(1))
blend_weight(state, 2, 1)
orientation_error_angle(np.eye(3), np.asfortranarray(np.eye(3)))
orientation_error_angle([[1, 0, 0], [0, 1, 0], [0, 0, 1]], np.eye(3))
# the drive's compiled tick (nsdrake.driver.tick): panda_wipe in lockstep, the wrench from the
# sensor's messages and from the external torques, the robot adding g and not
from nsdrake.driver.run import run_simulated
for source, adds in (("sensor", True), ("external_torque", False)):
    s = load_scenario("panda_wipe", duration=0.005)
    driver = dataclasses.replace(s.driver, force_source=source, robot_adds_gravity=adds)
    s = dataclasses.replace(s, driver=driver)
    assert run_simulated(s, realtime_rate=0.0, robot_adds_gravity=adds).failure is None
print("COMPILED", compiled)
# no kernel specialised twice: every nsdrake kernel this process holds has one list of types
import numba, sys as _sys
twice = [f"{name}.{k}{[str(s) for s in d.signatures]}" for name, module in list(_sys.modules.items())
         if name.startswith("nsdrake.") for k, d in vars(module).items()
         if isinstance(d, numba.core.registry.CPUDispatcher) and d.py_func.__module__ == name
         and len(d.signatures) > 1]
print("TWICE", twice)
"""


def test_every_shipped_scenario_and_way_to_run_it_needs_no_further_compile():
    """Issue 36, item 2: one compile covers every configuration. After compile_kernels
    (compiled once per install, or loaded from the cache), every shipped scenario (pose and
    position tasks, sweep, posture, joint limits or none, obstacles in closed form, by
    Drake's queries or none; 4 and 7 joints) run through the named systems, the fused
    system and a plain ControllerStep (its first t an int), the Panda with Drake's
    terms, a vendor's arm with OBJ meshes on its links near a ball (the obstacle row from
    Drake's queries; Pinocchio's and Drake's terms), the model's own terms and the
    selector's and orientation error's API with ints, a drive's compiled tick (both force
    sources, both gravity setups), compile nothing; and the process
    then holds each nsdrake kernel for one list of argument types only. Catches a
    configuration that specialises the compiled code (run_stages compiled per pose task,
    sweep, limits and obstacles: up to 16 versions), a time passed on as an int, a kernel
    called from Python with types the list of entry points lacks (a second compile notice
    in a later run: before issue 42's fix, activation and pack_criterion on mesh links),
    and a Python caller passing another layout than the stages (_jacobian_partials called
    with Drake's non-contiguous Jacobian rows: compiled twice)."""
    done = subprocess.run(
        [sys.executable, "-c", _EVERY_CONFIGURATION], capture_output=True, text=True, timeout=1800
    )
    assert done.returncode == 0, done.stderr[-3000:]
    assert done.stdout.strip().splitlines()[-2:] == ["COMPILED []", "TWICE []"], done.stdout[-3000:]


# A user's own arm with OBJ meshes on its links, a ball obstacle, a pose task (issue 42).
_MESH_OBSTACLE = """
import sys, tempfile
from pathlib import Path
import numpy as np
from pydrake.geometry import Sphere
from pydrake.math import RigidTransform
from nsdrake.control import ControllerConfig, ControllerModel, ControllerStep, Obstacle
from tests.vendor_arm import Q0, write_vendor_arm
arm = write_vendor_arm(Path(tempfile.mkdtemp()))
ball = Obstacle("ball", Sphere(0.03), RigidTransform([0.3, 0.0, 0.9]))
model = ControllerModel.from_file(arm.urdf, tool_frame="tool", task_axes=("x", "y", "z", "rx", "ry", "rz"),
                                  obstacles=[ball])
config = ControllerConfig(period=0.001)
config.desired_null_space.criteria.obstacle.gain = 1.0
step = ControllerStep(controller_model=model, config=config)
zero = np.zeros(3)
for k in range(3):
    R_d = np.array([1.0, 0, 0, 0])
    step.step(0.001 * k, Q0, np.zeros(7), None, np.zeros(3), zero, zero, None, R_d, zero, zero)
"""

# Prints, per nsdrake kernel in numba's cache, the argument types it is cached for.
_CACHED_SIGNATURES = """
import importlib
import numba
from nsdrake.control.kernels import PACKAGE, kernel_sources
for source in kernel_sources():
    name = ".".join(("nsdrake",) + source.relative_to(PACKAGE).with_suffix("").parts)
    module = importlib.import_module(name)
    for kernel, d in vars(module).items():
        if isinstance(d, numba.core.registry.CPUDispatcher) and d.py_func.__module__ == name:
            keys = d._cache._cache_file._load_index()
            if keys:
                print(f"{name}.{kernel}", len(keys), [str(k[0]) for k in keys])
"""


@pytest.mark.slow
def test_on_a_fresh_cache_a_user_s_commands_print_the_compile_notice_once(tmp_path):
    """Issue 36's and issue 42's acceptance: on a fresh kernel cache, `nsdrake run` of fig3,
    panda_wipe and priority_demo, a pose task given on the command line (panda_wipe held at
    its start orientation by a --config file), and a user's arm whose links are OBJ meshes
    near a ball obstacle (its obstacle row from Drake's queries) — five processes, as a
    user's commands — print the compile notice once in all: the first run compiles every
    configuration's kernels. And no kernel is in the cache for two lists of argument types
    (a kernel specialised twice compiles twice). Catches kernels compiled per configuration
    (before issue 36: fig3 compiled, then panda_wipe again), kernels only the obstacle row
    from Drake's queries calls from Python (before: activation and pack_criterion compiled
    in the mesh arm's process), and a caller passing another layout than the stages do (the
    closed-form distances called with Drake's column-major rotation: segments_box twice)."""
    env = os.environ | {"NUMBA_CACHE_DIR": str(tmp_path / "numba-cache")}
    (tmp_path / "pose.yaml").write_text("reference: {orientation: start}\n")
    run = [sys.executable, "-m", "nsdrake", "run"]
    short = ["--duration", "0.02", "--no-replay"]
    commands = {
        "fig3": [*run, "fig3", *short],
        "panda_wipe": [*run, "panda_wipe", *short],
        "priority_demo": [*run, "priority_demo", *short],
        "pose task": [*run, "panda_wipe", *short, "--config", str(tmp_path / "pose.yaml")],
        "mesh obstacle": [sys.executable, "-c", _MESH_OBSTACLE],
    }
    notices = {}
    for k, (name, command) in enumerate(commands.items()):
        out = ["--out", str(tmp_path / f"run{k}")] if command[:4] == run else []
        done = subprocess.run(
            [*command, *out], env=env, capture_output=True, text=True, timeout=1800, cwd=ROOT
        )
        assert done.returncode in (0, 1), done.stderr[-3000:]  # 1: a metric's bound on a short run
        notices[name] = done.stderr.count(NOTICE)
    assert notices == {"fig3": 1, "panda_wipe": 0, "priority_demo": 0, "pose task": 0, "mesh obstacle": 0}
    done = subprocess.run(
        [sys.executable, "-c", _CACHED_SIGNATURES], env=env, capture_output=True, text=True, cwd=ROOT
    )
    assert done.returncode == 0, done.stderr[-3000:]
    cached = done.stdout.splitlines()
    for kernel in ("front_stage", "torque_stage", "pinocchio_terms", "complete_terms"):
        assert any(line.startswith(f"nsdrake.control.stages.{kernel} 1 ") for line in cached), cached
    assert [line for line in cached if line.split()[1] != "1"] == []


def _children(pid: int) -> list[int]:
    """The processes whose parent is ``pid`` (from /proc)."""
    out = []
    for stat in Path("/proc").glob("[0-9]*/stat"):
        try:
            fields = stat.read_text().rsplit(")", 1)[1].split()
        except OSError:
            continue
        if int(fields[1]) == pid:
            out.append(int(stat.parent.name))
    return out


@pytest.mark.skipif(not Path("/proc/self/stat").exists(), reason="needs Linux's /proc")
def test_the_helper_compiling_for_a_killed_run_ends_with_it(tmp_path):
    """compile_kernels on an empty cache has a helper process compile half the kernels on
    the second core. A run killed meanwhile (SIGKILL: no handler, no cleanup) must not leave
    the helper compiling for a minute on a core of its own. Catches a helper that does not
    watch its parent (its stdin closing), or watches it only once it has imported nsdrake
    (seconds on a busy machine: at load 17 it outlived the test's 10 s)."""
    import signal
    import time

    env = os.environ | {"NUMBA_CACHE_DIR": str(tmp_path / "numba-cache")}
    run = subprocess.Popen(
        [sys.executable, "-c", "from nsdrake.control.kernels import compile_kernels; compile_kernels()"],
        env=env,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        assert run.stderr.readline().strip() == NOTICE  # the helper starts right after it
        deadline = time.monotonic() + 60.0
        while not (helpers := _children(run.pid)) and time.monotonic() < deadline:
            time.sleep(0.05)
        assert helpers, "no helper process started"
    finally:
        run.send_signal(signal.SIGKILL)
        run.wait()
    deadline = time.monotonic() + 10.0
    alive = helpers
    while alive and time.monotonic() < deadline:
        time.sleep(0.1)
        alive = [p for p in helpers if Path(f"/proc/{p}").exists() and "Z" not in _state(p)]
    for p in alive:  # the test's own cleanup, whatever the verdict
        os.kill(p, signal.SIGKILL)
    assert alive == [], "the helper went on compiling after its run was killed"
    left = list(Path(tempfile.gettempdir()).glob(f"{CLAIMS}{run.pid}-*"))
    assert left == [], "the killed run's claims folder was left behind"


def test_the_claims_folder_of_a_dead_compile_is_removed_and_a_live_one_s_kept(tmp_path):
    """A compile killed with its helper (both SIGKILLed, no cleanup) leaves its claims
    folder; the next compile removes it (kernels._remove_stale_claims). Catches folders
    left forever in the temporary folder, and a live compile's claims removed under it
    (both processes would then compile the kernels it had claimed)."""
    from nsdrake.control.kernels import _remove_stale_claims

    ended = subprocess.Popen([sys.executable, "-c", "pass"])
    ended.wait()  # reaped: its id names no process
    folders = {
        "dead": tmp_path / f"{CLAIMS}{ended.pid}-abc",
        "this process": tmp_path / f"{CLAIMS}{os.getpid()}-def",
        "its parent": tmp_path / f"{CLAIMS}{os.getppid()}-ghi",
        "not ours": tmp_path / f"{CLAIMS}jkl",
    }
    for folder in folders.values():
        folder.mkdir()
        (folder / "3").touch()  # a claim
    _remove_stale_claims(tmp_path)
    assert {name: folder.exists() for name, folder in folders.items()} == {
        "dead": False, "this process": True, "its parent": True, "not ours": True,
    }  # fmt: skip


def _state(pid: int) -> str:
    try:
        return Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
    except OSError:
        return "Z"


class _Kernel:
    """A stand-in for a numba dispatcher: compiling it takes a while and is logged."""

    def __init__(self, name: str, log: list):
        self.py_func, self.log = SimpleNamespace(__name__=name), log

    def compile(self, arguments):
        import threading
        import time

        self.log.append((threading.current_thread().name, self.py_func.__name__))
        time.sleep(0.02)


def test_the_two_processes_compile_each_missing_kernel_once(tmp_path):
    """compile_kernels' two processes take the missing kernels from one list
    (kernels._share, here in two threads over one claims folder): each kernel is compiled
    by one of them, and both get a share. Catches a claim that is not exclusive (both
    compile every kernel: twice the CPU time, no wall time saved) and a helper that takes
    nothing (the compile on one core)."""
    import threading

    from nsdrake.control.kernels import _share

    names = [f"kernel{k}" for k in range(16)]
    log: list = []
    workers = [
        threading.Thread(
            target=_share,
            args=([(_Kernel(n, log), ()) for n in names], list(range(16)), tmp_path),
            name=name,
        )
        for name in ("run", "helper")
    ]
    for w in workers:
        w.start()
    for w in workers:
        w.join()
    assert sorted(what for _, what in log) == sorted(names)
    assert {who for who, _ in log} == {"run", "helper"}


def test_kernels_compiled_with_plain_slice_errors_still_raise_them_and_only_they():
    """compile_kernels compiles with numba's plain message for an array assigned to a slice
    of another shape (kernels._plain_slice_errors: numba's message with both shapes formats
    strings in compiled code, linked into every kernel). Catches the error lost (a wrong-size
    write going through silently) and the change leaking out of the block (a user's kernels
    compiled afterwards must keep numba's message with the shapes)."""
    import numpy as np
    from numba import njit

    from nsdrake.control.kernels import _plain_slice_errors

    def assign(a, b):
        a[1:3] = b
        return a

    with _plain_slice_errors():
        inside = njit(assign)
        assert list(inside(np.zeros(4), np.ones(2))) == [0.0, 1.0, 1.0, 0.0]  # compiled here
    outside = njit(assign)
    with pytest.raises(ValueError, match="^cannot assign slice from input of different size$"):
        inside(np.zeros(4), np.ones(3))
    with pytest.raises(ValueError, match=r"of shape \(2,\) from input of shape \(3,\)"):
        outside(np.zeros(4), np.ones(3))
