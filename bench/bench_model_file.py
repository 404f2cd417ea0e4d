"""Benchmark: the controller's step on an arm loaded from model files, against the same arm
from its mesh-free URDF text (issue 36: "at the fast path's cost").

    python bench/bench_model_file.py [--calls N] [--repeats N]

The 7-joint arm of tests/vendor_arm.py (OBJ meshes, a package.xml, package:// and relative
URIs), written to a temporary folder, loaded by ``ControllerModel.from_file`` as a URDF, an
SDF and Drake model directives, and by ``ControllerModel.from_urdf`` from its mesh-free text
(the reference). Each gets a ``ControllerStep`` holding the full pose (task axes x … rz, no
obstacles, so the mesh only rides along); ``--calls`` calls at fresh states (a new q, q̇ each
call, as a robot's loop) are timed in process CPU time, the four models interleaved in
each of ``--repeats`` rounds so that all see the same machine load. Prints, per model, the
median CPU µs per call and its ratio to the reference; the last line is one JSON object.
The machine's load (``os.getloadavg``) is printed with the figures.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from nsdrake.control import ControllerConfig, ControllerModel, ControllerStep  # noqa: E402
from tests.vendor_arm import Q0, mesh_free_urdf, write_vendor_arm  # noqa: E402

POSE = ("x", "y", "z", "rx", "ry", "rz")


def stepper(model: ControllerModel):
    """A hold-the-pose step at Q0 and a function that calls it once at a fresh state."""
    step = ControllerStep(controller_model=model, config=ControllerConfig(period=0.001), task_axes=POSE)
    context = model.plant.CreateDefaultContext()
    model.plant.SetPositions(context, Q0)
    X = model.arm.tool_frame.CalcPoseInWorld(context)
    p, quaternion, zero = X.translation(), X.rotation().ToQuaternion().wxyz(), np.zeros(3)
    rng = np.random.default_rng(0)
    states = [(Q0 + 0.01 * rng.standard_normal(7), 0.1 * rng.standard_normal(7)) for _ in range(256)]
    tick = [0]

    def call():
        q, v = states[tick[0] % len(states)]
        step.step(tick[0] * 0.001, q, v, None, p, zero, zero, None, quaternion, zero, zero)
        tick[0] += 1

    return call


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--calls", type=int, default=5000)
    parser.add_argument("--repeats", type=int, default=5)
    args = parser.parse_args()
    arm = write_vendor_arm(Path(tempfile.mkdtemp()))
    models = {
        "urdf_text": ControllerModel.from_urdf(mesh_free_urdf(), tool_frame="tool", task_axes=POSE),
        "urdf_file": ControllerModel.from_file(arm.urdf, tool_frame="tool", task_axes=POSE),
        "sdf_file": ControllerModel.from_file(arm.sdf, tool_frame="tool", task_axes=POSE),
        "directives_file": ControllerModel.from_file(arm.directives, tool_frame="tool", task_axes=POSE),
    }
    calls = {name: stepper(model) for name, model in models.items()}
    for call in calls.values():  # warm-up: the first call compiles or loads the kernels
        for _ in range(200):
            call()
    times: dict[str, list[float]] = {name: [] for name in calls}
    for _ in range(args.repeats):
        for name, call in calls.items():
            start = time.process_time()
            for _ in range(args.calls):
                call()
            times[name].append((time.process_time() - start) / args.calls * 1e6)
    median = {name: float(np.median(t)) for name, t in times.items()}
    load = os.getloadavg()
    print(f"load {load[0]:.2f} {load[1]:.2f} {load[2]:.2f}: {args.calls} calls, {args.repeats} rounds")
    for name, us in median.items():
        dynamics = models[name].dynamics
        ratio = us / median["urdf_text"]
        print(f"{name:16s} {us:8.1f} µs CPU per step ({dynamics}), {ratio:.3f} of urdf_text")
    result = {f"{name}_step_us": round(us, 2) for name, us in median.items()}
    result |= {f"{name}_ratio": round(us / median["urdf_text"], 4) for name, us in median.items()}
    result["load1"] = round(load[0], 2)
    print(json.dumps(result))


if __name__ == "__main__":
    main()
