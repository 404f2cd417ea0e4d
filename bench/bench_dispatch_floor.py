"""Benchmark: what the controller diagram costs before any math.

    python bench/bench_dispatch_floor.py [--repeats N] [--steps N]

Builds the 4-joint (fig3) and 7-joint (Panda) controllers of bench_controller.py twice:
as they are, and with every Python system's computation replaced by the value it
produced on its first evaluation (each system still evaluates all its input ports and
writes its output, so the diagram, its ports and its caches are the same). The hot
step cost of the second is the floor that the Python LeafSystems themselves put under
any implementation of their math: the figure to compare with a per-step target.
Prints medians over ``--repeats`` runs; the last line is one JSON object.
"""

from __future__ import annotations

import argparse
import json
import statistics

from bench_controller import fig3_controller, panda_controller, step_cost

from nsdrake.control import systems


def _stored(calc, name):
    """calc(self, context, output) → evaluate the inputs, then write the first result again."""

    def stored(self, context, output):
        for i in range(self.num_input_ports()):
            self.get_input_port(i).Eval(context)
        memo = self.__dict__.setdefault("_bench_stored", {})
        abstract = hasattr(output, "get_mutable_value")
        if name not in memo:
            calc(self, context, output)
            memo[name] = output.get_value() if abstract else output.CopyToVector()
        elif abstract:
            output.set_value(memo[name])
        else:
            output.SetFromVector(memo[name])

    return stored


def replace_math_by_stored_values() -> None:
    """Patches the systems' classes (before a controller is built): their output ports were
    declared with these methods, so patching after construction would change nothing."""
    for cls, name in (
        (systems.RobotTermsSystem, "_calc_terms"),
        (systems.ImpedanceController, "_calc"),
        (systems.PrioritySelector, "_calc"),
        (systems.NullSpaceController, "_calc"),
        (systems.ActuatorLimitsSystem, "_calc"),
        (systems.CriteriaSystem, "_calc"),
        (systems.SelfMotionSweep, "_calc"),
    ):
        setattr(cls, name, _stored(getattr(cls, name), name))


def measure(repeats: int, steps: int) -> dict[str, float]:
    out = {}
    for label, make in (("4dof", fig3_controller), ("7dof", panda_controller)):
        controller, q0 = make()
        out[label] = statistics.median(step_cost(controller, q0, steps, seed=k) for k in range(repeats))
    return out


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=5, help="runs per figure (median)")
    parser.add_argument("--steps", type=int, default=3000, help="controller evaluations per run")
    args = parser.parse_args()
    real = measure(args.repeats, args.steps)
    replace_math_by_stored_values()
    floor = measure(args.repeats, args.steps)
    for label in real:
        print(
            f"controller step, {label}: {real[label]:6.1f} µs; with the math replaced by stored values "
            f"{floor[label]:6.1f} µs"
        )
    print(
        json.dumps(
            {f"step_us_{k}": round(v, 1) for k, v in real.items()}
            | {f"floor_us_{k}": round(v, 1) for k, v in floor.items()}
        )
    )


if __name__ == "__main__":
    main()
