"""Small helpers shared by the LeafSystems."""

from __future__ import annotations

from pydrake.common.value import AbstractValue
from pydrake.systems.framework import ValueProducer


def python_value_producer(compute) -> ValueProducer:
    """A ValueProducer for a cache entry holding whatever ``compute(context)`` returns."""
    return ValueProducer(
        allocate=lambda: AbstractValue.Make(object()),
        calc=lambda context, value: value.set_value(compute(context)),
    )
