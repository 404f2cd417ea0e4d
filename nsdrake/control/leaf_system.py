"""nsdrake's ``LeafSystem``: Drake's, whose Python callbacks (output calcs, update events)
release the context Drake lent them when they raise.

Drake calls a callback with its context and output as *borrowed* references: Python
wrappers of C++ objects that Drake owns and frees. An exception leaving the callback
carries a traceback that holds the callback's frames, and with them those wrappers; a
caller that keeps the exception (``pytest.raises``, a log, ``except … as e`` inside a
reference cycle) keeps the wrappers alive after Drake freed the context. pybind11 still
maps the freed address to the old wrapper, so a context allocated later at that address
(``plant.CreateDefaultContext()``) is handed back *as the old wrapper* and its owning
pointer dropped: the new context is freed at once and its first use is a segmentation
fault in Drake (seen: ``DependencyTracker::NoteValueChange`` from
``SetPositionsAndVelocities``, after the controller's ``ControllerInputError`` tests).

:func:`released_on_error` clears the locals of every frame the exception passed through
inside the callback (:func:`traceback.clear_frames`) and drops the callback's own
arguments, so the error keeps its message and the lines of its traceback but no borrowed
Drake object.
"""

from __future__ import annotations

import functools
import traceback

from pydrake.systems.framework import LeafSystem as DrakeLeafSystem


def released_on_error(callback):
    """``callback`` (called by Drake with borrowed context, output or state), whose
    exceptions hold no frame locals below it and not its arguments (module docstring)."""

    @functools.wraps(callback)
    def call(*args):
        try:
            return callback(*args)
        except BaseException as error:
            traceback.clear_frames(error.__traceback__)  # the callee frames (this one runs on)
            del args
            raise

    return call


def _wrapped(args: tuple, kwargs: dict, position: int, names: tuple[str, ...]) -> tuple[tuple, dict]:
    """The arguments with the callback at ``position`` (or keyword in ``names``) wrapped."""
    args = list(args)
    if len(args) > position and callable(args[position]):
        args[position] = released_on_error(args[position])
    for name in names:
        if callable(kwargs.get(name)):
            kwargs[name] = released_on_error(kwargs[name])
    return tuple(args), kwargs


class LeafSystem(DrakeLeafSystem):
    """Drake's LeafSystem, its declared callbacks wrapped by :func:`released_on_error`."""

    def DeclareVectorOutputPort(self, *args, **kwargs):
        args, kwargs = _wrapped(args, kwargs, 2, ("calc",))
        return super().DeclareVectorOutputPort(*args, **kwargs)

    def DeclareAbstractOutputPort(self, *args, **kwargs):
        args, kwargs = _wrapped(args, kwargs, 2, ("calc",))
        return super().DeclareAbstractOutputPort(*args, **kwargs)

    def DeclarePeriodicDiscreteUpdateEvent(self, *args, **kwargs):
        args, kwargs = _wrapped(args, kwargs, 2, ("update",))
        return super().DeclarePeriodicDiscreteUpdateEvent(*args, **kwargs)

    def DeclarePeriodicUnrestrictedUpdateEvent(self, *args, **kwargs):
        args, kwargs = _wrapped(args, kwargs, 2, ("update",))
        return super().DeclarePeriodicUnrestrictedUpdateEvent(*args, **kwargs)
