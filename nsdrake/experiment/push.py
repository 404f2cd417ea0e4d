"""A push on a link: an external force pulse, for disturbance experiments (issue 19).

The force F_W (world frame) acts at the origin of the named body from ``start_time`` for
``duration``, through the plant's ``applied_spatial_force`` input (Drake's
``ExternallyAppliedSpatialForce``); zero before and after. The controller is not told:
it sees the push only through the state it causes (the force sensor under the plate does
not measure it).

(No ``from __future__ import annotations`` here: Drake's ``yaml_load_typed`` reads the
dataclass field types at run time.)
"""

import math
from collections.abc import Iterator
from dataclasses import dataclass, field

import numpy as np
from pydrake.common.value import AbstractValue
from pydrake.multibody.math import SpatialForce
from pydrake.multibody.plant import ExternallyAppliedSpatialForce
from pydrake.multibody.tree import BodyIndex

from nsdrake.control.leaf_system import LeafSystem


@dataclass
class PushConfig:
    """An external force pulse on one link of the arm; off while ``duration`` is 0."""

    # The body pushed (a link of the arm, e.g. panda_link4, the elbow) [-].
    body: str = ""
    # The force on the body's origin, world frame [N].
    force: list[float] = field(default_factory=lambda: [0.0, 0.0, 0.0])
    # When the push starts [s].
    start_time: float = 0.0
    # How long it lasts; 0: no push [s].
    duration: float = 0.0

    @property
    def enabled(self) -> bool:
        return self.duration > 0


def push_problems(push: PushConfig, duration: float | None = None) -> Iterator[tuple[str, str]]:
    """(field, problem) of a push that cannot be applied, or would never act: one starting
    at or after the run's end (``duration`` [s], when given). The body is checked against
    the plant when the push is added (:func:`unknown_body_problem`)."""
    force = push.force
    if not isinstance(force, list) or len(force) != 3 or not all(_finite(f) for f in force):
        yield "push.force", f"must be [fx, fy, fz], three finite numbers [N], got {force!r}"
    for name in ("start_time", "duration"):
        value = getattr(push, name)
        if not _finite(value) or value < 0:
            yield f"push.{name}", f"must be a finite number >= 0, got {value!r}"
    if _finite(push.duration) and push.duration > 0 and not push.body:
        yield "push.body", "a push needs the name of the body it pushes"
    if (
        push.enabled
        and duration is not None
        and _finite(push.start_time)
        and _finite(duration)
        and push.start_time >= duration
    ):
        yield (
            "push.start_time",
            f"{push.start_time:g} s is at or after the run's end (duration {duration:g} s): "
            "the push would never act",
        )


def _finite(value) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value)


def push_force(t: float, push: PushConfig) -> np.ndarray:
    """F_W at time t: the push's force inside [start, start + duration), else 0. (3,) [N]."""
    inside = push.start_time <= t < push.start_time + push.duration
    return np.asarray(push.force, dtype=float) if inside else np.zeros(3)


class LinkPush(LeafSystem):
    """The push as a list of one ``ExternallyAppliedSpatialForce`` (module docstring).

    .. pydrake_system::

        name: LinkPush
        output_ports:
        - spatial_forces
    """

    def __init__(self, *, plant, push: PushConfig):
        super().__init__()
        self._push = push
        self._body = plant.GetBodyByName(push.body).index()
        self.DeclareAbstractOutputPort(
            "spatial_forces",
            lambda: AbstractValue.Make([ExternallyAppliedSpatialForce()]),
            self._calc,
            prerequisites_of_calc={self.time_ticket()},
        )

    def _calc(self, context, output) -> None:
        applied = ExternallyAppliedSpatialForce()
        applied.body_index = self._body
        applied.p_BoBq_B = np.zeros(3)
        applied.F_Bq_W = SpatialForce(tau=np.zeros(3), f=push_force(context.get_time(), self._push))
        output.set_value([applied])


def add_push(builder, plant, push: PushConfig):
    """A :class:`LinkPush` into ``plant``'s applied_spatial_force input (the body must be
    in the plant: :func:`unknown_body_problem`); None without a push."""
    if not push.enabled:
        return None
    system = builder.AddNamedSystem("link_push", LinkPush(plant=plant, push=push))
    builder.Connect(system.get_output_port(), plant.get_applied_spatial_force_input_port())
    return system


def unknown_body_problem(plant, push: PushConfig) -> str | None:
    """Why ``push.body`` cannot be pushed in ``plant``, or None: no such body, or one that
    cannot move (the world, or a body welded to it: the push would do nothing)."""
    if not push.enabled:
        return None
    fixed = {body.index() for body in plant.GetBodiesWeldedTo(plant.world_body())}
    moving = sorted(
        plant.get_body(BodyIndex(i)).name() for i in range(plant.num_bodies()) if BodyIndex(i) not in fixed
    )
    if not plant.HasBodyNamed(push.body):
        return f"no body named {push.body!r} in the station; the bodies that move: {', '.join(moving)}"
    if plant.GetBodyByName(push.body).index() in fixed:
        return (
            f"{push.body!r} cannot move (it is the world or welded to it): a push on it would do nothing; "
            f"the bodies that move: {', '.join(moving)}"
        )
    return None
