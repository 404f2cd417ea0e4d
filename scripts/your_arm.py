"""The figures of docs/your_arm.md ("Your arm from its vendor's package"), on two arms of
the example-robot-data package (PyPI): a Universal Robots UR5 and a Franka Panda.

    python scripts/your_arm.py --out DIR

writes DIR/load/table.md, what loading each file as shipped finds and does (the joints,
the root welded to the world, the joints locked, Drake's parser warnings, the effort
limits and damping the file declares, what a declared 1 kg payload adds to the model's
gravity torque), then runs ``nsdrake run docs/examples/ARM_press.yaml`` for each arm
(DIR/ARM_press/: the run's whole folder) and writes DIR/table.md, the press's figures from
each run's metrics.json and traces.csv. scripts/regenerate_results.py --family your_arm
runs it into runs/results/your_arm and copies both tables to docs/results/your_arm/.
Exit status 2 without the package (the line says how to install it), 1 if a run fails
its bounds.
"""

from __future__ import annotations

import argparse
import json
import logging
import math
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
PACKAGE = "example-robot-data"


@dataclass(frozen=True)
class Arm:
    name: str  # the row's first cell
    file: str  # below the package's folder
    tool_frame: str
    task_axes: tuple[str, ...]
    joints: tuple[str, ...] | None  # None: every joint of the file
    scenario: str  # docs/examples/SCENARIO.yaml


ARMS = (
    Arm(
        "UR5",
        "robots/ur_description/urdf/ur5_robot.urdf",
        "tool0",
        ("x", "y", "z"),
        None,
        "ur5_press",
    ),
    Arm(
        "Panda",
        "robots/panda_description/urdf/panda.urdf",
        "panda_hand_tcp",
        ("x", "y", "z", "rx", "ry", "rz"),
        tuple(f"panda_joint{k}" for k in range(1, 8)),
        "panda_press",
    ),
)
PAYLOAD_MASS = 1.0  # [kg], 5 cm along the tool frame's z


def load_row(arm: Arm, folder: Path) -> str:
    """What ControllerModel.from_file finds in ``arm``'s file as shipped, as a table row."""
    from pydrake.multibody.plant import MultibodyPlant

    import nsdrake
    from nsdrake.control.controller import torque_limits
    from nsdrake.control.model_files import Payload, parse_model_file
    from nsdrake.experiment.scenario import load_scenario

    packages = {PACKAGE: folder}
    common = dict(packages=packages, tool_frame=arm.tool_frame, task_axes=arm.task_axes, joints=arm.joints)
    logging.getLogger("nsdrake").setLevel(logging.ERROR)  # the lines it says are in the row
    model = nsdrake.ControllerModel.from_file(folder / arm.file, **common)
    loaded = nsdrake.ControllerModel.from_file(
        folder / arm.file, payload=Payload(mass=PAYLOAD_MASS, com=(0.0, 0.0, 0.05)), **common
    )
    bare = MultibodyPlant(0.0)  # the file's own joints, nothing chosen or locked
    parse_model_file(bare, folder / arm.file, packages, "file")
    bare.Finalize()
    in_file = [bare.get_joint(j) for j in bare.GetJointIndices() if bare.get_joint(j).num_velocities() == 1]
    parsed = model.parsed
    warnings = sum(len(v) for v in parsed.warnings.values())
    locked = ", ".join(f"`{name}`" for name in parsed.locked) or "none"
    limits = torque_limits(nsdrake.ControllerConfig(), model)
    damping = model.arm.damping
    scenario = load_scenario(ROOT / "docs" / "examples" / f"{arm.scenario}.yaml")
    q0 = np.array([scenario.arm.initial_positions[name] for name in model.joint_names])
    context = model.plant.CreateDefaultContext()
    g = model.arm.terms(context, q0, np.zeros(model.n), False).g
    g_loaded = loaded.arm.terms(loaded.plant.CreateDefaultContext(), q0, np.zeros(model.n), False).g
    shoulder = int(np.argmax(np.abs(g_loaded - g)))
    return (
        f"| {arm.name} | `{arm.file}` | {len(in_file)} | {model.n} | "
        f"{', '.join(f'`{b}`' for b in parsed.welded) or 'none'} | {locked} | {warnings} | "
        f"{_range(limits)} | {_range(damping)} | "
        f"{abs(g_loaded[shoulder] - g[shoulder]):.3g} | `{model.joint_names[shoulder]}` |"
    )


def _range(values) -> str:
    low, high = float(np.min(values)), float(np.max(values))
    return f"{low:g}" if math.isclose(low, high) else f"{low:g}–{high:g}"


LOAD_HEADER = (
    "| arm | file | joints in the file | the arm's joints | root welded to the world | joints locked "
    "| Drake's parser warnings | effort limits [N m] | damping [N m s/rad] "
    f"| {PAYLOAD_MASS:g} kg payload declared: the largest gravity torque it adds [N m] | on joint |"
)


def press_row(arm: Arm, out: Path) -> tuple[str, bool]:
    """Runs ``nsdrake run docs/examples/SCENARIO.yaml`` into out/SCENARIO; its table row and
    whether every bound was met."""

    folder = out / arm.scenario
    command = [sys.executable, "-m", "nsdrake", "run", f"docs/examples/{arm.scenario}.yaml"]
    done = subprocess.run([*command, "--out", str(folder), "--overwrite", "--no-replay"], cwd=ROOT)
    row, met = row_of(arm, folder)
    return row, done.returncode == 0 and met


def row_of(arm: Arm, folder: Path) -> tuple[str, bool]:
    """The press's row from a run's folder, and whether every bound was met."""
    from nsdrake.experiment.traces import Traces

    body = json.loads((folder / "metrics.json").read_text())
    m = {name: entry["value"] for name, entry in body["metrics"].items()}
    bounded = [e for e in body["metrics"].values() if e.get("passed") is not None]
    met = sum(1 for e in bounded if e["passed"])
    traces = Traces.read_csv(folder / "traces.csv")
    window = traces["t"] >= m["window_start"]
    q = traces.block("q")[window]
    motion = float(np.max(q.max(axis=0) - q.min(axis=0)))
    orientation = _figure(m, "orientation_error_max")
    swivel = f"{m['swivel_range']:.3g}" if "swivel_range" in m else "–"
    row = (
        f"| {arm.name} | `nsdrake run docs/examples/{arm.scenario}.yaml` | {m['first_contact_time']:.3g} "
        f"| {m['force_error_rms']:.2g} | {_figure(m, 'force_error_max')} "
        f"| {_micro(m, 'position_error_rms')} | {_micro(m, 'position_error_max')} "
        f"| {orientation} | {motion:.3g} | {swivel} | {m['joint_speed_ratio_max']:.2f} "
        f"| {met} of {len(bounded)} |"
    )
    return row, met == len(bounded)


def _micro(metrics: dict, name: str) -> str:
    """A length the run's check computes, in µm (:func:`_figure`)."""
    return _figure(metrics, name, 1e6)


def _figure(metrics: dict, name: str, scale: float = 1.0) -> str:
    """A figure the run's check computes (times ``scale``), to two digits, or – (the check
    has none such)."""
    return f"{metrics[name] * scale:.2g}" if name in metrics else "–"


PRESS_HEADER = (
    "| arm | command | first contact [s] | force error RMS [N] | force error max [N] "
    "| position error RMS [µm] | position error max [µm] | orientation error max [°] "
    "| null-space motion: largest joint travel [rad] "
    "| elbow swivel [rad] | largest joint speed / limit | bounds met |"
)


LOAD_TITLE = (
    "# your_arm: loading the files as shipped\n\n"
    f"Each file of {PACKAGE} loaded untouched by `nsdrake.ControllerModel.from_file` (the Panda with "
    "`joints=` its seven arm joints): the joints the file has with one degree of freedom, the "
    "arm's, the root body that floated and was welded to the world, the joints locked, Drake's "
    "parser warnings (one line said for all), the `<limit effort>` and `<dynamics damping>` the "
    f"file declares, and the largest change a declared {PAYLOAD_MASS:g} kg payload (5 cm along "
    "the tool frame's z) makes to the model's gravity torque at the press's start pose."
)
PRESS_TITLE = (
    "# your_arm\n\n"
    "`nsdrake run` of the two standalone scenario files in docs/examples/: the arm comes down "
    "onto the table, presses 10 N and holds its tool while the null space moves the joints. "
    "The figures are the run's metrics.json (from 0.5 s after first contact); the null-space "
    "motion is the largest travel of one joint over that window, from traces.csv; bounds met "
    "counts every figure with a bound (the pose check for the UR5, self_motion for the Panda)."
)


def _table(title: str, header: str, rows: list[str]) -> str:
    return "\n".join([title, "", header, "|" + "---|" * header.count("| "), *rows]) + "\n"


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, required=True, help="folder for the tables and the runs")
    args = parser.parse_args()
    from nsdrake.station.models import installed_package

    folder = installed_package(PACKAGE)
    if folder is None:
        print(f"your_arm: {PACKAGE} is not installed: pip install 'nsdrake[arms]'", file=sys.stderr)
        return 2
    out = args.out.resolve()
    (out / "load").mkdir(parents=True, exist_ok=True)
    rows = [load_row(arm, folder) for arm in ARMS]
    (out / "load" / "table.md").write_text(_table(LOAD_TITLE, LOAD_HEADER, rows))
    results = [press_row(arm, out) for arm in ARMS]
    (out / "table.md").write_text(_table(PRESS_TITLE, PRESS_HEADER, [r for r, _ in results]))
    print(f"your_arm: wrote {out / 'load' / 'table.md'} and {out / 'table.md'}")
    return 0 if all(ok for _, ok in results) else 1


if __name__ == "__main__":
    sys.exit(main())
