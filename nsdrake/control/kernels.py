"""nsdrake's compiled kernels: compiled once per install, announced while it happens, never stale.

The controller's arithmetic runs in numba kernels (``@njit(cache=True)``). numba compiles
a kernel on its first call and keeps the machine code in ``__pycache__`` beside the
source, so the first run after an install compiles and later runs load.

Two things numba leaves to its user:

- **A notice.** Compiling takes tens of seconds, during which a run prints nothing.
  :func:`announce_compiling` listens to numba's compile events and prints one line, once
  per process, when the first of nsdrake's kernels starts compiling (not when they load
  from the cache).
- **Stale machine code.** numba invalidates a cached kernel when *its own* source file
  changes, not when a kernel it calls, defined in another file, does: after an edit or a
  partial update the cache would keep running the old callee. :func:`refresh_cache`
  fingerprints every nsdrake source file that defines kernels and, when the fingerprint
  changes, deletes nsdrake's cached kernels (only those, only in the package's own
  ``__pycache__`` folders), so that they compile anew once.
"""

from __future__ import annotations

import hashlib
import sys
from pathlib import Path

from numba.core import config, event
from numba.core.caching import _CacheLocator

PACKAGE = Path(__file__).resolve().parents[1]  # the nsdrake folder
STAMP = "nsdrake-kernels.stamp"
# The one line a first run prints; the time is fig3's on 2 cores (docs/architecture.md).
NOTICE = "nsdrake: compiling nsdrake's kernels, once per install (about 40 s)…"


def kernel_sources(package: Path = PACKAGE) -> list[Path]:
    """The package's source files that define numba kernels, sorted."""
    return sorted(p for p in package.rglob("*.py") if "@njit" in p.read_text(encoding="utf-8"))


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
    """Prints :data:`NOTICE` on stderr when the first nsdrake kernel starts compiling, and
    counts the compiles under way (numba nests them: a kernel compiles its callees)."""

    def __init__(self):
        self.printed = False
        self.depth = 0

    def on_start(self, ev):
        self.depth += 1
        if self.printed:
            return
        module = getattr(getattr(ev.data.get("dispatcher"), "py_func", None), "__module__", "") or ""
        if module.startswith("nsdrake."):
            self.printed = True
            sys.stderr.write(NOTICE + "\n")  # one write: workers compiling at once print whole lines
            sys.stderr.flush()

    def on_end(self, ev):
        self.depth = max(0, self.depth - 1)


_notice = _CompileNotice()


def compiling() -> bool:
    """Whether numba is compiling a kernel in this process now (after :func:`announce_compiling`).
    An exception raised into the compiler, e.g. KeyboardInterrupt by a signal handler, can
    land in a finalizer, where Python prints it and drops it."""
    return _notice.depth > 0


def announce_compiling() -> None:
    """Registers the compile notice (once per process)."""
    if not getattr(announce_compiling, "done", False):
        event.register("numba:compile", _notice)
        announce_compiling.done = True
