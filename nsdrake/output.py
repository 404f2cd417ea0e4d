"""Output folders: claimed atomically, marked with what nsdrake wrote, never taken from a user.

A run claims its folder by creating the manifest ``.nsdrake-run`` in it with O_EXCL: of
two runs that reach the same folder at once, exactly one succeeds, and the other moves on
to the next default folder (``runs/NAME-2``, …) or, with an explicit ``--out``, stops.
When the run ends (done or failed), the manifest lists every file and folder it wrote.
``--overwrite`` removes exactly those, and refuses a folder holding anything else.

Every problem is an :class:`OutputFolderError` with a one-line message naming the path.
"""

from __future__ import annotations

import os
from pathlib import Path

MANIFEST = ".nsdrake-run"
_HEADER = (
    "# nsdrake wrote the files and folders listed below (paths relative to this folder);\n"
    "# nsdrake run/compare --overwrite removes exactly these and refuses a folder holding anything else.\n"
)


class OutputFolderError(ValueError):
    """The output folder cannot be used without losing what is in it, or cannot be made."""


def _why(e: OSError) -> str:
    return e.strerror or " ".join(str(e).split())


def _file_in_the_way(path: Path) -> Path | None:
    """The first of ``path`` and its parents that exists and is not a folder."""
    for p in [*reversed(path.parents), path]:
        if p.exists() and not p.is_dir():
            return p
    return None


def _make_folders(path: Path) -> None:
    """``mkdir -p path``, with every failure as one line."""
    blocker = _file_in_the_way(path)
    if blocker is not None:
        where = "exists and is not a folder" if blocker == path else f"{blocker} is a file, not a folder"
        raise OutputFolderError(f"{path}: {where}")
    try:
        path.mkdir(parents=True, exist_ok=True)
    except OSError as e:
        raise OutputFolderError(f"{path}: cannot create the folder: {_why(e)}") from None


def _claim(folder: Path) -> bool:
    """Creates the manifest in ``folder`` if nobody has: True if this call did."""
    try:
        fd = os.open(folder / MANIFEST, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o644)
    except FileExistsError:
        return False
    except OSError as e:
        raise OutputFolderError(f"{folder}: cannot write in the folder: {_why(e)}") from None
    with os.fdopen(fd, "w") as f:
        f.write(_HEADER)
    return True


def _entries(folder: Path) -> list[str]:
    """Everything below ``folder`` but the manifest: files as "a/b", folders as "a/" (symbolic
    links as files, never followed)."""
    found = []
    for top, dirs, files in os.walk(folder):
        rel = Path(top).relative_to(folder)
        for d in list(dirs):
            if os.path.islink(os.path.join(top, d)):
                dirs.remove(d)
                files.append(d)
            else:
                found.append(f"{(rel / d).as_posix()}/")
        found += [(rel / f).as_posix() for f in files]
    return sorted(e for e in found if e != MANIFEST)


def _remove_previous_run(folder: Path) -> None:
    """Removes what an earlier nsdrake run wrote into ``folder``; refuses, removing
    nothing, if the folder holds anything that run's manifest does not list."""
    try:
        listed = {
            line for line in (folder / MANIFEST).read_text().splitlines() if line and not line.startswith("#")
        }
    except FileNotFoundError:
        raise OutputFolderError(
            f"{folder}: --overwrite refused: the folder has no {MANIFEST}, so nsdrake did not write it; "
            "move its files away or choose another --out"
        ) from None
    except (OSError, UnicodeDecodeError) as e:
        raise OutputFolderError(f"{folder}: cannot read {MANIFEST}: {' '.join(str(e).split())}") from None
    entries = _entries(folder)
    foreign = [e for e in entries if e not in listed]
    if foreign:
        more = f" (and {len(foreign) - 1} more)" if len(foreign) > 1 else ""
        raise OutputFolderError(
            f"{folder}: --overwrite refused: nsdrake did not write {foreign[0]}{more}; "
            "move it away or choose another --out"
        )
    try:
        for e in sorted(entries, key=lambda e: e.count("/") - e.endswith("/"), reverse=True):
            path = folder / e
            if e.endswith("/"):
                path.rmdir()  # empty now: everything in it was listed and removed first
            else:
                path.unlink(missing_ok=True)
        (folder / MANIFEST).unlink(missing_ok=True)
    except OSError as e:
        raise OutputFolderError(f"{folder}: --overwrite: cannot remove {e.filename}: {_why(e)}") from None


def prepare_output_folder(out: Path, *, overwrite: bool) -> Path:
    """Claims the folder ``out`` (making it and its parents if needed).

    A non-empty folder is refused unless ``overwrite``; with it, what an earlier nsdrake
    run wrote there is removed first, and a folder holding anything else is refused.
    """
    out = Path(out)
    _make_folders(out)
    if any(out.iterdir()):
        if not overwrite:
            raise OutputFolderError(f"{out}: folder is not empty; choose another --out or pass --overwrite")
        _remove_previous_run(out)
    if not _claim(out):
        raise OutputFolderError(
            f"{out}: another nsdrake run claimed this folder just now; choose another --out"
        )
    return out


def default_output_folder(name: str, root: Path = Path("runs")) -> Path:
    """Claims runs/NAME, or runs/NAME-2, -3, …: the first that is new or empty and that no
    other run claims first."""
    root = Path(root)
    _make_folders(root)
    k = 1
    while True:
        candidate = root / (name if k == 1 else f"{name}-{k}")
        k += 1
        try:
            os.mkdir(candidate)
        except FileExistsError:
            if not candidate.is_dir() or any(candidate.iterdir()):
                continue
        except OSError as e:
            raise OutputFolderError(f"{candidate}: cannot create the folder: {_why(e)}") from None
        if _claim(candidate):
            return candidate


def record_written(folder: Path) -> None:
    """Lists in the manifest everything now in ``folder`` (which its run claimed empty or
    emptied), so that a later --overwrite may remove it. Does nothing in a folder that no
    run claimed; on a write error, leaves the manifest as it was (a later --overwrite
    then refuses rather than guesses)."""
    manifest = Path(folder) / MANIFEST
    if not manifest.is_file():
        return
    tmp = manifest.with_name(f"{MANIFEST}.{os.getpid()}.tmp")
    try:
        tmp.write_text(_HEADER + "".join(f"{e}\n" for e in _entries(folder) if e != tmp.name))
        os.replace(tmp, manifest)
    except OSError:
        tmp.unlink(missing_ok=True)
