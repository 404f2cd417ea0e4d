"""Small helpers shared by the LeafSystems."""

from __future__ import annotations

from pydrake.common.value import AbstractValue
from pydrake.systems.framework import ValueProducer


def declare_scratch(system, create):
    """A cache entry holding ``create()`` (a model context) that ``system`` may write q
    and q̇ into while computing an output: per-context scratch memory (no
    prerequisites, never recomputed), so no model context is shared between the
    system's contexts. Read it with
    ``entry.get_mutable_cache_entry_value(context).GetMutableValueOrThrow()``."""
    return system.DeclareCacheEntry(
        description="scratch model context",
        value_producer=ValueProducer(
            allocate=lambda: AbstractValue.Make(create()),
            calc=lambda context, value: None,
        ),
        prerequisites_of_calc={system.nothing_ticket()},
    )
