"""nsdrake's compiled kernels: compiled once per install, announced while it happens, never stale.

The controller's arithmetic runs in numba kernels (``@njit(cache=True)``). numba compiles
a kernel on its first call and keeps the machine code in ``__pycache__`` beside the
source, so the first run after an install compiles and later runs load.

Three things numba leaves to its user:

- **Once for every configuration.** numba compiles a kernel anew for each new mix of
  argument types, and a kernel that a run does not call is not compiled: a kernel
  specialised per configuration, or one that only some scenarios reach, compiles again in
  a later run. So the controller's stages take the configuration as values, never as
  types (:func:`nsdrake.control.stages.run_stages`), and :func:`compile_kernels`, called
  where a controller is built, compiles every kernel nsdrake calls from Python with the
  types of its call sites, in one go: one compile per install covers a pose or a position
  task, a sweep, joint limits, obstacles and any joint count (issue 36). Each kernel
  compiles for one list of argument types only (the callers convert their arrays): no
  kernel is specialised twice.
- **Both cores.** numba compiles in one thread, and one process compiles one kernel at a
  time. :func:`compile_kernels` therefore has a second process (:func:`_helper`) share
  the work: both walk one list of the kernels missing from the cache, the largest first,
  and each compiles the kernels it is the first to claim (:func:`_share`), into numba's
  on-disk cache; this process then loads the helper's. For this the controller's stages
  are kernels of their own, called in turn from Python (:func:`nsdrake.control.stages.run_stages`):
  numba compiles a kernel's callees into it (it links their code in, then optimises and
  emits it again), so one kernel for the whole tick was one process's work, twice. numba
  writes each cache file whole (by rename), but it saves a kernel by reading that
  kernel's index, adding the new entry and writing the index back: two processes saving
  two versions of one kernel (a callee both compile, e.g. for two literal arguments)
  could lose one, or file one's machine code under the other's types. So while
  :func:`compile_kernels` runs, every save holds a lock shared by the processes
  (:func:`_saves_locked`).

- **A notice.** Compiling takes tens of seconds, during which a run prints nothing.
  :func:`announce_compiling` listens to numba's compile events and prints one line, once
  per process, when the first of nsdrake's kernels starts compiling (not when they load
  from the cache); :func:`compile_kernels` prints it when it starts the helper.
- **Stale machine code.** numba invalidates a cached kernel when *its own* source file
  changes, not when a kernel it calls, defined in another file, does: after an edit or a
  partial update the cache would keep running the old callee. :func:`refresh_cache`
  fingerprints every nsdrake source file that defines kernels and, when the fingerprint
  changes, deletes nsdrake's cached kernels (only those, only in the package's own
  ``__pycache__`` folders), so that they compile anew once.
"""

from __future__ import annotations

import contextlib
import hashlib
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from numba.core import config, event
from numba.core.caching import _CacheLocator
from numba.core.extending import overload

PACKAGE = Path(__file__).resolve().parents[1]  # the nsdrake folder
STAMP = "nsdrake-kernels.stamp"
CLAIMS = "nsdrake-kernels-"  # the claims folder's prefix in the temporary folder, then "<pid>-"
# The one line a first run prints; the time is compile_kernels' wall time on 2 quiet cores of
# the project's machine kind: about the CPU time of the busier of its two processes, 49 and
# 54 CPU-s in a first fig3 run of 67.2 s wall on a quiet machine (docs/architecture.md);
# a whole first fig3 run took 38.9 s wall on 2026-12-02's idle host (main 6395e08).
NOTICE = "nsdrake: compiling nsdrake's kernels, once per install (under a minute on 2 cores)…"


def kernel_sources(package: Path = PACKAGE) -> list[Path]:
    """The package's source files that define numba kernels (or functions compiled into
    them, ``@register_jitable``), sorted."""
    return sorted(p for p in package.rglob("*.py") if _defines_kernels(p.read_text(encoding="utf-8")))


def _defines_kernels(text: str) -> bool:
    return "@njit" in text or "@register_jitable" in text


def fingerprint(sources: list[Path], package: Path = PACKAGE) -> str:
    digest = hashlib.sha256()
    for path in sources:
        digest.update(str(path.relative_to(package)).encode())
        digest.update(path.read_bytes())
    return digest.hexdigest()


def cache_folder(source: Path) -> Path:
    """Where numba keeps the cached kernels of ``source``: ``__pycache__`` beside it, or
    with NUMBA_CACHE_DIR set, the folder numba derives from the source's folder there."""
    if not config.CACHE_DIR:
        return source.parent / "__pycache__"
    return Path(config.CACHE_DIR) / _CacheLocator.get_suitable_cache_subpath(str(source))


def refresh_cache(package: Path = PACKAGE) -> bool:
    """Deletes nsdrake's cached kernels if any kernel source changed since they were
    compiled (module docstring); True if it did. A read-only install keeps its cache (it
    cannot have been edited in place). The stamp lives with the cache it describes
    (:func:`cache_folder`), so that a run with another NUMBA_CACHE_DIR neither deletes
    nor vouches for the default cache."""
    sources = kernel_sources(package)
    stamp = cache_folder(package / "__init__.py") / STAMP
    now = fingerprint(sources, package)
    try:
        if stamp.read_text() == now:
            return False
    except OSError:
        pass
    try:
        for path in sources:
            for cached in cache_folder(path).glob(f"{path.stem}.*.nb[ic]"):
                cached.unlink(missing_ok=True)
        stamp.parent.mkdir(parents=True, exist_ok=True)
        stamp.write_text(now)
    except OSError:
        return False
    return True


class _CompileNotice(event.Listener):
    """Prints :data:`NOTICE` on stderr when the first nsdrake kernel starts compiling,
    counts the compiles under way (numba nests them: a kernel compiles its callees) and
    adds up the wall time spent in them (outermost compiles only)."""

    def __init__(self, clock=time.monotonic):
        self.printed = False
        self.depth = 0
        self.clock, self.seconds, self.started = clock, 0.0, 0.0

    def on_start(self, ev):
        if self.depth == 0:
            self.started = self.clock()
        self.depth += 1
        if self.printed:
            return
        module = getattr(getattr(ev.data.get("dispatcher"), "py_func", None), "__module__", "") or ""
        if module.startswith("nsdrake."):
            self.announce()

    def announce(self):
        """Prints :data:`NOTICE`, once."""
        if not self.printed:
            self.printed = True
            sys.stderr.write(NOTICE + "\n")  # one write: workers compiling at once print whole lines
            sys.stderr.flush()

    @contextlib.contextmanager
    def waiting(self):
        """A block that counts as a compile (:func:`compiling`, :meth:`compile_seconds`):
        waiting for the helper process that compiles kernels for this one."""
        if self.depth == 0:
            self.started = self.clock()
        self.depth += 1
        try:
            yield
        finally:
            self.on_end(None)

    def on_end(self, ev):
        self.depth = max(0, self.depth - 1)
        if self.depth == 0:
            self.seconds += self.clock() - self.started

    def compile_seconds(self) -> float:
        """Wall time spent compiling so far, the compile under way included [s]."""
        return self.seconds + (self.clock() - self.started if self.depth > 0 else 0.0)


_notice = _CompileNotice()


def compiling() -> bool:
    """Whether numba is compiling a kernel in this process now (after :func:`announce_compiling`).
    An exception raised into the compiler, e.g. KeyboardInterrupt by a signal handler, can
    land in a finalizer, where Python prints it and drops it."""
    return _notice.depth > 0


def compile_seconds() -> float:
    """Wall time this process has spent compiling numba kernels so far [s] (after
    :func:`announce_compiling`): what a progress line leaves out of a simulation's time
    (:mod:`nsdrake.reporting.progress`)."""
    return _notice.compile_seconds()


def announce_compiling() -> None:
    """Registers the compile notice (once per process)."""
    if not getattr(announce_compiling, "done", False):
        event.register("numba:compile", _notice)
        announce_compiling.done = True


def _entry_points() -> list[tuple[str, str, tuple]]:
    """Every kernel nsdrake calls from Python, with the argument types of each call site:
    (module, name, argument types), one list of types per kernel (the callers convert their
    arrays to it: a second list would compile the kernel a second time). Kernels called
    only by kernels compile with their callers (a kernel marked ``inline="always"`` is
    compiled into them, not on its own: called from Python too, it is listed here). The
    controller's stages take float64 and int64 arrays, C-contiguous, never a
    configuration-dependent type (:func:`nsdrake.control.stages.run_stages`); the others
    take the arrays Pinocchio and Drake return (column-major matrices, read-only vectors)."""
    from numba.core import types

    def A(dtype: str, ndim: int, layout: str = "C", readonly: bool = False):
        return types.Array(getattr(types, dtype), ndim, layout, readonly=readonly)

    f1, f2, f3, i1 = A("float64", 1), A("float64", 2), A("float64", 3), A("int64", 1)
    i64, f64 = types.int64, types.float64
    f2F, b2 = A("float64", 2, "F"), A("bool_", 2)
    u1, u2 = A("uint8", 1), A("uint8", 2)
    return [
        # the controller's stages (nsdrake.control.stages.run_stages and terms_stage), the largest
        # first (each process takes the next free kernel: the last to end ends the compile)
        ("nsdrake.control.stages", "front_stage", (i64, f64, f64, f1, i1, i1, f1, f2, f1, f1)),
        ("nsdrake.control.stages", "torque_stage", (i64, f64, f1, i1, i1, f1, f2, f1, f1, f1, f1)),
        ("nsdrake.control.stages", "pinocchio_terms",
         (f2F, f1, f1, f2F, f2F, A("float64", 3, "A", readonly=True), f2F, f1, f1, f1, f1, i1, i1, f1)),
        ("nsdrake.control.stages", "complete_terms", (f1, f1, i1, i1)),  # both terms' paths
        ("nsdrake.control.layout", "terms_size", (i1,)),
        ("nsdrake.control.layout", "tick_size", (i1,)),
        ("nsdrake.control.layout", "_take", (f1, i64, i64)),
        ("nsdrake.control.layout", "input_fault", (f1, i64)),
        # the obstacle row from Drake's queries (nsdrake.control.plan)
        ("nsdrake.control.stages", "pack_criterion", (f1, f1, f64, f64, f64)),
        ("nsdrake.control.smoothing", "activation", (f64, f64)),
        # the model (nsdrake.control.model, nsdrake.control.dynamics): Drake's and Pinocchio's arrays
        ("nsdrake.control.model", "symmetric_and_inverse", (f2F,)),
        ("nsdrake.control.dynamics", "derived_terms", (f2, f2, f3, f1)),
        ("nsdrake.control.dynamics", "_jacobian_partials", (f2, f2, b2, b2, i1, i1)),
        # the obstacle criterion by Drake's queries (nsdrake.control.criteria.obstacle)
        ("nsdrake.control.criteria.obstacle", "_axis_segments", (f3, f2, f2, f1)),
        ("nsdrake.control.criteria.obstacle", "_in_body_frames", (f3, A("float64", 2, "A"))),
        ("nsdrake.control.criteria.distance", "segments_box", (f2, f2, f2, f1, f1)),
        ("nsdrake.control.criteria.distance", "segments_sphere", (f2, f2, f1, f64)),
        # Fig. 1's selector from Python (nsdrake.control.priority's select_mode, ...)
        ("nsdrake.control.priority", "select_mode_code", (f64, f64, f64, i64, f1)),
        ("nsdrake.control.priority", "switch_state_update", (f1, f64, i64, f1)),
        ("nsdrake.control.priority", "blend_weight_code", (f64, f64, f64)),
        # the station, the run's metrics and the studies' measures
        ("nsdrake.station.force_sensor", "contact_wrench", (f2F, f1, f1)),
        ("nsdrake.control.orientation", "orientation_error", (f2, f2)),
        ("nsdrake.control.null_space_laws", "posture_target", (f1, f1, f64, f64, f64)),
        # the drive's tick (nsdrake.driver.loop, controller_side): LCM bytes in, a command's out
        ("nsdrake.driver.tick", "take_statuses", (u2, i1, i64, u1, i1, f1, f2, f3, f1)),
        ("nsdrake.driver.tick", "finish_tick", (f1, f1, types.boolean, f1, f1, f1, f2, i1, u1, f1)),
        ("nsdrake.driver.tick", "robot_torques", (f1, f1, types.boolean, f1, f1)),
        ("nsdrake.driver.tick", "decode_status", (u1, i64, u1, f1, f1, i1)),
        ("nsdrake.driver.tick", "decode_force_torque", (A("uint8", 1, readonly=True), u1, f1, f1)),
    ]  # fmt: skip


def _dispatchers() -> list[tuple[object, tuple]]:
    import importlib

    return [(getattr(importlib.import_module(m), name), args) for m, name, args in _entry_points()]


def _cached(dispatcher, arguments: tuple) -> bool:
    """Whether numba's cache holds ``dispatcher`` compiled for ``arguments`` (or this
    process already has it), without loading it."""
    if tuple(arguments) in dispatcher.overloads:
        return True
    cache = dispatcher._cache
    try:
        key = cache._index_key(arguments, dispatcher.targetctx.codegen())
        return key in cache._cache_file._load_index()
    except Exception:  # numba's private API moved: take it as not cached (the helper only helps)
        return False


@contextlib.contextmanager
def _saves_locked():
    """A block in which numba saves each cached kernel holding an exclusive lock on one
    file beside the stamp (:func:`refresh_cache`), so that processes compiling at once
    never interleave a kernel index's read and write (module docstring)."""
    try:
        import fcntl

        from numba.core.caching import IndexDataCacheFile
    except ImportError:  # no POSIX locks, or numba's internals moved: saves as numba does
        yield
        return
    lock_path = cache_folder(PACKAGE / "__init__.py") / "nsdrake-kernels.lock"
    original = IndexDataCacheFile.save

    def save(self, key, data):
        try:
            lock = open(lock_path, "ab")  # noqa: SIM115 (held across the save below)
        except OSError:
            return original(self, key, data)
        with lock:
            fcntl.flock(lock, fcntl.LOCK_EX)
            return original(self, key, data)

    IndexDataCacheFile.save = save
    try:
        yield
    finally:
        IndexDataCacheFile.save = original


def _slice_mismatch(src_shapes, index_shape):
    """What a kernel compiled by :func:`compile_kernels` calls when an array assigned to a
    slice has another shape than the slice (numba's ``raise_with_shape_context``)."""
    raise NotImplementedError  # compiled only


@overload(_slice_mismatch)
def _slice_mismatch_impl(src_shapes, index_shape):
    def impl(src_shapes, index_shape):
        raise ValueError("cannot assign slice from input of different size")

    return impl


@contextlib.contextmanager
def _plain_slice_errors():
    """A block in which a slice assignment's shape error compiles to numba's plain message
    (:func:`_slice_mismatch`) instead of its message with both shapes: that one formats
    strings in compiled code (``str.join``, ``str`` of ints, for each tuple length: 41 of
    the 231 compiles of :func:`compile_kernels`), and its code is linked into, re-optimised
    and emitted again in every kernel that assigns to a slice: without it, 0.92 of the
    compile's CPU time in one process (docs/architecture.md). The error is never raised by
    nsdrake's kernels (the layout fixes every shape), so nothing they compute changes; a
    user's own kernels, compiled outside this block, keep numba's message."""
    try:
        from numba.np import arrayobj

        original = arrayobj.raise_with_shape_context
    except (ImportError, AttributeError):  # numba's internals moved: its own message
        yield
        return
    arrayobj.raise_with_shape_context = _slice_mismatch
    try:
        yield
    finally:
        arrayobj.raise_with_shape_context = original


def compile_kernels(helper: bool = True) -> None:
    """Compiles (or loads from numba's cache) every kernel nsdrake calls from Python, with
    the types of its call sites (:func:`_entry_points`), once per process. A first run
    after an install thus compiles, in one go, the kernels of every configuration: a
    pose task or a position task, a sweep, joint limits, obstacles, any joint count; a
    later run of any scenario finds them all in the cache (issue 36). Called where a
    controller is built (:class:`nsdrake.control.plan.ControllerPlan`).

    When kernels are missing from the cache, a second process (``helper``) and this one
    share the work (:func:`_share`): each takes the next kernel of :func:`_entry_points`
    that neither has taken, until none is left; this one then waits for the helper and
    loads what it compiled. When none is missing, nothing is loaded here: a process loads
    the kernels it calls, at their first call (a run of fig3 calls a third of them; the
    drive's and the obstacle queries' kernels stay on disk)."""
    if getattr(compile_kernels, "done", False):
        return
    with _saves_locked(), _plain_slice_errors():
        _compile(_dispatchers(), helper)
    compile_kernels.done = True


def _compile(kernels: list[tuple[object, tuple]], helper: bool) -> None:
    missing = [k for k, (d, a) in enumerate(kernels) if not _cached(d, a)]
    if not missing:  # all in numba's cache: each loads at its first call, if this process calls it
        return
    if helper and (os.cpu_count() or 1) > 1:
        if len(missing) > 1:
            # A compile from the notice on (compiling(): a Ctrl-C then ends the run at once),
            # waiting for the helper included.
            _remove_stale_claims()
            prefix = f"{CLAIMS}{os.getpid()}-"
            with _notice.waiting(), tempfile.TemporaryDirectory(prefix=prefix) as claims:
                _notice.announce()
                started, compiled = _start_helper(claims), False
                try:
                    if started is not None:
                        _share(kernels, missing, Path(claims))
                    compiled = True
                finally:
                    if started is not None:
                        _wait(started, compiled)
    for dispatcher, arguments in kernels:  # loads what the helper compiled, compiles what it did not
        dispatcher.compile(arguments)


def _remove_stale_claims(folder: Path | None = None) -> None:
    """Deletes the claims folders (:func:`_share`) of compiles whose process is gone: a run
    killed outright (SIGKILL, no cleanup) leaves its folder behind; the next compile on
    this machine removes it. A folder's name carries its process's id (``CLAIMS<pid>-``);
    a folder of a live process (or of another user's: no permission to signal it) stays."""
    import shutil

    for path in Path(folder or tempfile.gettempdir()).glob(f"{CLAIMS}*-*"):
        pid = path.name[len(CLAIMS) :].split("-", 1)[0]
        if not pid.isdigit() or int(pid) == os.getpid():
            continue
        try:
            os.kill(int(pid), 0)
        except ProcessLookupError:
            shutil.rmtree(path, ignore_errors=True)
        except OSError:  # alive, another user's
            continue


def _share(kernels, missing: list[int], claims: Path) -> None:
    """Compiles, in :func:`_entry_points`' order, each kernel of ``missing`` that this
    process is the first to claim: a file created in ``claims``, a folder shared with the
    other process (creation is atomic: one of two processes creating it gets an error)."""
    for k in missing:
        try:
            os.close(os.open(claims / f"{k}", os.O_CREAT | os.O_EXCL | os.O_WRONLY))
        except FileExistsError:
            continue
        dispatcher, arguments = kernels[k]
        dispatcher.compile(arguments)


def _start_helper(claims: str) -> subprocess.Popen | None:
    """Starts the helper process sharing the compile (:func:`_share`) through the folder
    ``claims``. It ends when this process ends (a thread of its own, started before it
    imports nsdrake, reads its stdin until it closes; it then deletes the claims folder,
    which a process killed outright leaves behind) and at a Ctrl-C in the terminal (SIGINT
    ends it: nothing to keep but whole cache files)."""
    code = (  # the watch first: importing nsdrake takes seconds on a busy machine
        "import os, shutil, sys, threading\n"
        "def watch():\n"
        "    sys.stdin.buffer.read()\n"  # the run's process ended: its claims folder is not needed
        "    shutil.rmtree(sys.argv[1], ignore_errors=True)\n"
        "    os._exit(1)\n"
        "threading.Thread(target=watch, daemon=True).start()\n"
        "from nsdrake.control.kernels import _helper\n"
        "_helper()"
    )
    try:
        return subprocess.Popen(
            [sys.executable, "-c", code, claims],
            stdin=subprocess.PIPE,
            stdout=subprocess.DEVNULL,
            stderr=subprocess.DEVNULL,
            env=os.environ | {"NSDRAKE_KERNELS_HELPER": "1"},
        )
    except OSError:
        return None


def _wait(process: subprocess.Popen, wait: bool) -> None:
    """Waits for the helper to end (``wait``; else ends it at once: this process failed),
    and ends it if this process is interrupted meanwhile."""
    try:
        if wait:
            process.wait()
    finally:
        if process.poll() is None:
            process.kill()
            process.wait()
        with contextlib.suppress(OSError):
            process.stdin.close()


def _helper() -> None:
    """The helper process (:func:`compile_kernels`): compiles its share of the missing
    kernels (:func:`_share`, the claims folder its argument) into numba's cache, silently."""
    import signal

    signal.signal(signal.SIGINT, signal.SIG_DFL)
    _notice.printed = True  # the parent printed the notice
    kernels = _dispatchers()
    with _saves_locked(), _plain_slice_errors():
        missing = [k for k, (d, a) in enumerate(kernels) if not _cached(d, a)]
        _share(kernels, missing, Path(sys.argv[1]))
