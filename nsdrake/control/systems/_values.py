"""Per-context memory of the controller's systems: the values their abstract ports and
cache entries hold. Drake clones a context's values with ``copy.deepcopy``, so each
class here says what a copy is (numbers copied, model scratch made anew, never shared)."""

from __future__ import annotations

import numpy as np
from pydrake.common.value import AbstractValue
from pydrake.systems.framework import ValueProducer

from nsdrake.control.plan import ControllerPlan


class TermsValue:
    """The model terms at one state (:func:`nsdrake.control.layout.terms_views`): the value
    of the ``robot_terms`` port, one flat buffer rewritten in place at every state."""

    def __init__(self, buffer: np.ndarray):
        self.buffer = buffer


class ScratchValue:
    """Model scratch memory (:meth:`nsdrake.control.model.ControllerModel.create_scratch`):
    a copy is a fresh scratch of the same model, as a copy needs no stale numbers."""

    def __init__(self, plan: ControllerPlan):
        self.plan = plan
        self.scratch = plan.create_scratch()

    def __deepcopy__(self, memo):
        return ScratchValue(self.plan)


class FrontValue:
    """Stages 1 and 2 at one state (the fused system's cache entry): the terms, the
    criteria, and the scratch they were computed in."""

    def __init__(self, plan: ControllerPlan):
        self.plan = plan
        self.scratch = plan.create_scratch()
        self.terms = plan.allocate_terms()
        self.criteria = plan.allocate_criteria()

    def __deepcopy__(self, memo):
        out = FrontValue(self.plan)
        out.terms[:], out.criteria[:] = self.terms, self.criteria
        return out


def declare_value_cache(system, description: str, create, calc=None, prerequisites=None):
    """A cache entry holding ``create()``, allocated per context, that ``calc(context, value)``
    rewrites in place (``value`` the object itself) when one of ``prerequisites`` changed;
    without ``calc`` it is scratch memory, never recomputed. Read it with
    :func:`cached`."""
    if calc is None:
        producer = ValueProducer(allocate=lambda: AbstractValue.Make(create()), calc=lambda c, v: None)
        prerequisites = {system.nothing_ticket()}
    else:
        producer = ValueProducer(
            allocate=lambda: AbstractValue.Make(create()),
            calc=lambda context, value: calc(context, value.get_mutable_value()),
        )
    return system.DeclareCacheEntry(
        description=description, value_producer=producer, prerequisites_of_calc=prerequisites
    )


def cached(entry, context):
    """The object in a :func:`declare_value_cache` entry: evaluated (computed if out of
    date), or for scratch memory, as it is."""
    return entry.Eval(context)


def scratch(entry, context):
    """The object in a scratch entry of :func:`declare_value_cache` (never computed)."""
    return entry.get_mutable_cache_entry_value(context).GetMutableValueOrThrow()
