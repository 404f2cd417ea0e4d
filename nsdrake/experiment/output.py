"""Output folders: claimed atomically, marked with what nsdrake wrote, never taken from a user.

A command claims its folder by creating the manifest ``.nsdrake-run`` in it with O_EXCL:
of two commands that reach the same folder at once, exactly one succeeds, and the other
moves on to the next default folder (``runs/NAME-2``, …) or, with an explicit ``--out``,
stops. The manifest names the process that holds the claim, and lists, *before* it is
written, every file the command may write there (:func:`declare`): a command killed at
any moment (SIGKILL, a power cut) leaves a manifest that covers everything it wrote.
When the command ends (done or failed), :func:`record_written` trims the list to what
exists and releases the claim.

``--overwrite`` (:func:`prepare_output_folder`) removes exactly the files listed, and
refuses, removing nothing, a folder holding anything else, a folder without a manifest,
a manifest that lists anything outside the folder (``../x``, an absolute path, a path
through a symbolic link in the folder: a manifest is a file anyone can edit), and a
folder whose claim is held by a live nsdrake process. A claim whose process is gone
(killed) is stale: it is reclaimed like a finished one. Sweeps take over their own folder
to resume (:func:`take_over`) under the same rules.

Every problem is an :class:`OutputFolderError` with a one-line message naming the path.
"""

from __future__ import annotations

import errno
import os
import socket
import stat
from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path, PurePosixPath

MANIFEST = ".nsdrake-run"
_LOCK = ".nsdrake-run.lock"  # held while a command takes over an existing claim
_OWNER = "# owner: "  # the manifest line naming the process that holds the claim
_HEADER = (
    "# nsdrake wrote the files listed below (paths relative to this folder; a folder ends in /);\n"
    "# --overwrite removes exactly these and refuses a folder holding anything else.\n"
)


class OutputFolderError(ValueError):
    """The output folder cannot be used without losing what is in it, or cannot be made."""


def _why(e: OSError) -> str:
    return e.strerror or " ".join(str(e).split())


def _own_files(name: str) -> bool:
    """The manifest and its helpers (lock, temporary copies): never a user's entry."""
    return name == MANIFEST or name.startswith(MANIFEST + ".")


# --- who holds a claim ------------------------------------------------------------------


def _start_time(pid: int) -> str:
    """The process's start time in clock ticks since boot (Linux), so that a reused pid is
    not mistaken for the claim's process; "" where /proc is not there."""
    try:
        stat = Path(f"/proc/{pid}/stat").read_text()
    except OSError:
        return ""
    return stat.rsplit(")", 1)[-1].split()[19]


def _owner_line() -> str:
    pid = os.getpid()
    return f"{_OWNER}{socket.gethostname()} {pid} {_start_time(pid)}".rstrip() + "\n"


def _holder_alive(owner: str | None) -> int | None:
    """The pid of the live process other than this one that holds a claim, else None."""
    if not owner:
        return None
    host, pid_text, *start = owner.split()
    try:
        pid = int(pid_text)
    except ValueError:
        return None
    if host != socket.gethostname() or pid == os.getpid():
        return None  # another machine's claim cannot be checked: it is treated as stale
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return None
    except PermissionError:
        pass  # alive, another user's
    if start and _start_time(pid) not in ("", start[0]):
        return None  # the pid was reused by another process
    return pid


@dataclass
class Manifest:
    listed: set[str]  # entries, files as "a/b", folders as "a/"
    owner: str | None  # "HOST PID START" of the process holding the claim, None when released


def read_manifest(folder: Path) -> Manifest | None:
    """The folder's manifest, or None if it has none; unreadable is one line."""
    path = Path(folder) / MANIFEST
    try:
        text = path.read_text()
    except FileNotFoundError:
        return None
    except (OSError, UnicodeDecodeError) as e:
        raise OutputFolderError(f"{folder}: cannot read {MANIFEST}: {' '.join(str(e).split())}") from None
    listed, owner = set(), None
    for line in text.splitlines():
        if line.startswith(_OWNER):
            owner = line[len(_OWNER) :].strip() or None
        elif line and not line.startswith("#"):
            listed.add(line)
    return Manifest(listed, owner)


def _with_folders(entries: Iterable[str]) -> set[str]:
    """The entries and every folder above them ("a/b/c" brings "a/" and "a/b/")."""
    out = set()
    for e in entries:
        out.add(e)
        for parent in PurePosixPath(e.rstrip("/")).parents:
            if str(parent) != ".":
                out.add(f"{parent.as_posix()}/")
    return out


# --- making and claiming ----------------------------------------------------------------


def _file_in_the_way(path: Path) -> Path | None:
    """The first of ``path`` and its parents that exists and is not a folder."""
    for p in [*reversed(path.parents), path]:
        if p.exists() and not p.is_dir():
            return p
    return None


def _make_folders(path: Path, created: list[Path] | None = None) -> None:
    """``mkdir -p path``, with every failure as one line; appends to ``created`` the folders
    it made, outermost first."""
    blocker = _file_in_the_way(path)
    if blocker is not None:
        where = "exists and is not a folder" if blocker == path else f"{blocker} is a file, not a folder"
        raise OutputFolderError(f"{path}: {where}")
    missing = [p for p in [*reversed(path.parents), path] if not p.exists()]
    try:
        path.mkdir(parents=True, exist_ok=True)
    except OSError as e:
        raise OutputFolderError(f"{path}: cannot create the folder: {_why(e)}") from None
    if created is not None:
        created += missing


def _claim(folder: Path) -> bool:
    """Creates the manifest in ``folder`` if nobody has: True if this call did."""
    try:
        fd = os.open(folder / MANIFEST, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o644)
    except FileExistsError:
        return False
    except OSError as e:
        raise OutputFolderError(f"{folder}: cannot write in the folder: {_why(e)}") from None
    with os.fdopen(fd, "w") as f:
        f.write(_HEADER + _owner_line())
    return True


def entries(folder: Path) -> list[str]:
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
    return sorted(e for e in found if not _own_files(e))


def _write_manifest(folder: Path, listed: Iterable[str], owner: bool) -> None:
    manifest = Path(folder) / MANIFEST
    tmp = manifest.with_name(f"{MANIFEST}.{os.getpid()}.tmp")
    body = _HEADER + (_owner_line() if owner else "") + "".join(f"{e}\n" for e in sorted(listed))
    try:
        tmp.write_text(body)
        os.replace(tmp, manifest)
    except OSError as e:
        tmp.unlink(missing_ok=True)
        raise OutputFolderError(f"{folder}: cannot write {MANIFEST}: {_why(e)}") from None


def _refuse_if_held(folder: Path, manifest: Manifest) -> None:
    pid = _holder_alive(manifest.owner)
    if pid is not None:
        raise OutputFolderError(
            f"{folder}: nsdrake process {pid} is still writing into this folder; wait for it or choose "
            "another --out"
        )


def foreign_entries(folder: Path, manifest: Manifest) -> list[str]:
    """What is in ``folder`` that its manifest does not list (a user's files)."""
    listed = _with_folders(manifest.listed)
    return [e for e in entries(folder) if e not in listed]


def refuse_foreign(folder: Path, manifest: Manifest) -> None:
    foreign = foreign_entries(folder, manifest)
    if foreign:
        more = f" (and {len(foreign) - 1} more)" if len(foreign) > 1 else ""
        raise OutputFolderError(
            f"{folder}: --overwrite refused: nsdrake did not write {foreign[0]}{more}; "
            "move it away or choose another --out"
        )


def unsafe_entry(folder: Path, entry: str) -> str | None:
    """Why the manifest entry ``entry`` names something outside ``folder`` (an absolute path,
    a ``..`` or empty component, a path through a symbolic link inside the folder), else
    None. A manifest is a file anyone can edit or ship in a zipped run folder: only a plain
    relative path that stays inside the folder may be removed."""
    if not entry or "\0" in entry:
        return "an empty or binary path"
    if entry.startswith("/"):
        return "an absolute path"
    parts = entry.rstrip("/").split("/")
    if any(p in ("", ".", "..") for p in parts):
        return "a path outside the folder" if ".." in parts else "a path that is not plain"
    inside = Path(folder)
    for p in parts[:-1]:
        inside = inside / p
        try:
            if stat.S_ISLNK(os.lstat(inside).st_mode):
                return f"a path through the symbolic link {inside.relative_to(folder).as_posix()}"
        except FileNotFoundError:
            return None  # nothing there to remove
        except OSError as e:
            return f"a path that cannot be checked ({_why(e)})"
    return None


def refuse_unsafe(folder: Path, listed: Iterable[str]) -> None:
    """Refuses, before anything is removed, a manifest that lists a path outside ``folder``
    (:func:`unsafe_entry`)."""
    for e in sorted(listed):
        why = unsafe_entry(folder, e)
        if why is not None:
            raise OutputFolderError(
                f"{folder}: --overwrite refused: its {MANIFEST} lists {e!r}, {why}; nsdrake never writes "
                "outside its folder, so the manifest was edited: nothing was removed"
            )


def _remove_one(top: int, entry: str) -> None:
    """Removes ``entry`` below the open folder ``top`` without following a symbolic link on the
    way (each folder opened with O_NOFOLLOW relative to its parent, so a link swapped in after
    :func:`refuse_unsafe` is not followed either): a file or a link is unlinked, a folder
    removed only if empty; what does not exist is skipped."""
    parts = entry.rstrip("/").split("/")
    opened = []
    try:
        fd = top
        for p in parts[:-1]:
            try:
                fd = os.open(p, os.O_RDONLY | os.O_DIRECTORY | os.O_NOFOLLOW, dir_fd=fd)
            except FileNotFoundError:
                return
            opened.append(fd)
        try:
            mode = os.lstat(parts[-1], dir_fd=fd).st_mode
        except FileNotFoundError:
            return
        if entry.endswith("/"):
            if stat.S_ISDIR(mode):
                try:
                    os.rmdir(parts[-1], dir_fd=fd)
                except OSError as e:
                    if e.errno not in (errno.ENOTEMPTY, errno.EEXIST):
                        raise
        elif not stat.S_ISDIR(mode):
            os.unlink(parts[-1], dir_fd=fd)
    finally:
        for fd in opened:
            os.close(fd)


def remove_listed(folder: Path, listed: Iterable[str]) -> None:
    """Removes the ``listed`` entries that exist (files, then the folders they leave empty),
    never anything outside ``folder``: a list naming such a path is refused first, removing
    nothing (:func:`refuse_unsafe`)."""
    listed = list(listed)
    refuse_unsafe(folder, listed)
    listed = _with_folders(listed)
    try:
        top = os.open(folder, os.O_RDONLY | os.O_DIRECTORY)
    except OSError as e:
        raise OutputFolderError(f"{folder}: --overwrite: cannot open the folder: {_why(e)}") from None
    try:
        for e in sorted(listed, key=lambda e: e.count("/") - e.endswith("/"), reverse=True):
            try:
                _remove_one(top, e)
            except OSError as err:
                raise OutputFolderError(f"{folder}: --overwrite: cannot remove {e}: {_why(err)}") from None
    finally:
        os.close(top)


def _manifest_or_refuse(folder: Path) -> Manifest:
    manifest = read_manifest(folder)
    if manifest is None:
        raise OutputFolderError(
            f"{folder}: --overwrite refused: the folder has no {MANIFEST}, so nsdrake did not write it; "
            "move its files away or choose another --out"
        )
    return manifest


def _remove_previous_run(folder: Path) -> None:
    """Removes what an earlier nsdrake command wrote into ``folder``; refuses, removing
    nothing, a folder without a manifest, one holding anything its manifest does not
    list, and one whose claim a live process still holds."""
    manifest = _manifest_or_refuse(folder)
    _refuse_if_held(folder, manifest)
    refuse_unsafe(folder, manifest.listed)
    refuse_foreign(folder, manifest)
    remove_listed(folder, manifest.listed)
    try:
        (folder / MANIFEST).unlink(missing_ok=True)
    except OSError as e:
        raise OutputFolderError(f"{folder}: --overwrite: cannot remove {MANIFEST}: {_why(e)}") from None


def prepare_output_folder(out: Path, *, overwrite: bool, created: list[Path] | None = None) -> Path:
    """Claims the folder ``out`` (making it and its parents if needed; those it made are
    appended to ``created``, for :func:`release_unused`).

    A non-empty folder is refused unless ``overwrite``; with it, what an earlier nsdrake
    command wrote there is removed first, and a folder holding anything else is refused.
    """
    out = Path(out)
    _make_folders(out, created)
    if any(out.iterdir()):
        if not overwrite:
            raise OutputFolderError(f"{out}: folder is not empty; choose another --out or pass --overwrite")
        _remove_previous_run(out)
    if not _claim(out):
        raise OutputFolderError(
            f"{out}: another nsdrake run claimed this folder just now; choose another --out"
        )
    return out


def default_output_folder(name: str, root: Path = Path("runs"), created: list[Path] | None = None) -> Path:
    """Claims runs/NAME, or runs/NAME-2, -3, …: the first that is new or empty and that no
    other run claims first (the folders it made are appended to ``created``)."""
    root = Path(root)
    _make_folders(root, created)
    k = 1
    while True:
        candidate = root / (name if k == 1 else f"{name}-{k}")
        k += 1
        made = False
        try:
            os.mkdir(candidate)
            made = True
        except FileExistsError:
            if not candidate.is_dir() or any(candidate.iterdir()):
                continue
        except OSError as e:
            raise OutputFolderError(f"{candidate}: cannot create the folder: {_why(e)}") from None
        if _claim(candidate):
            if made and created is not None:
                created.append(candidate)
            return candidate


def release_unused(folder: Path, created: Iterable[Path] = ()) -> None:
    """Undoes a claim on ``folder`` that wrote nothing (the command failed or was stopped
    before its first file): removes the manifest, then each folder of ``created`` (the
    folders the claim made) that is empty, innermost first. A folder holding anything
    besides the manifest is left as it is; so is everything when this fails."""
    folder = Path(folder)
    try:
        if not folder.is_dir() or entries(folder):
            return
        (folder / MANIFEST).unlink(missing_ok=True)
        for path in sorted(created, key=lambda p: len(p.parts), reverse=True):
            if path.is_dir() and not any(path.iterdir()):
                path.rmdir()
    except (OSError, OutputFolderError):
        pass


def take_over(folder: Path) -> Manifest:
    """Takes over the claim on ``folder`` that an earlier nsdrake command made (to resume or
    to replace its work); refuses a folder without a manifest and one whose claim a live
    process holds. Two commands taking over at once: one succeeds, the other is refused."""
    folder = Path(folder)
    manifest = _manifest_or_refuse(folder)
    refuse_unsafe(folder, manifest.listed)
    _refuse_links(folder)
    lock = folder / _LOCK
    for attempt in range(2):
        try:
            fd = os.open(lock, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o644)
        except FileExistsError:
            holder = _holder_alive(_read_quietly(lock))
            if holder is not None or attempt:
                raise OutputFolderError(
                    f"{folder}: another nsdrake process is taking this folder over; choose another --out"
                ) from None
            lock.unlink(missing_ok=True)  # left by a killed process
            continue
        except OSError as e:
            raise OutputFolderError(f"{folder}: cannot write in the folder: {_why(e)}") from None
        with os.fdopen(fd, "w") as f:
            f.write(_owner_line()[len(_OWNER) :])
        break
    try:
        manifest = read_manifest(folder) or manifest
        _refuse_if_held(folder, manifest)
        _write_manifest(folder, manifest.listed, owner=True)
    finally:
        lock.unlink(missing_ok=True)
    return manifest


def _refuse_links(folder: Path) -> None:
    """A folder taken over is written into: a symbolic link in it (nsdrake never makes one)
    could lead a write outside it."""
    for e in entries(folder):
        if os.path.islink(folder / e.rstrip("/")):
            raise OutputFolderError(
                f"{folder}: holds the symbolic link {e.rstrip('/')}, which nsdrake never writes; "
                "move it away or choose another --out"
            )


def _read_quietly(path: Path) -> str | None:
    try:
        return path.read_text().strip() or None
    except OSError:
        return None


def declare(folder: Path, entries: Iterable[str]) -> None:
    """Lists ``entries`` (paths relative to ``folder``) in its manifest *before* they are
    written, so that whatever happens next, a later --overwrite knows them as nsdrake's.
    Does nothing in a folder that no command claimed (a user's own call)."""
    manifest = Path(folder) / MANIFEST
    if not manifest.is_file():
        return
    lines = "".join(f"{e}\n" for e in entries)
    try:
        with manifest.open("a") as f:
            f.write(lines)
    except OSError as e:
        raise OutputFolderError(f"{folder}: cannot write {MANIFEST}: {_why(e)}") from None


def record_written(folder: Path) -> None:
    """At the end of a command (done or failed): the manifest keeps the declared entries
    that exist, with the folders above them, and the claim is released. Nothing that was
    not declared is listed, so a file a user put there meanwhile stays theirs. Does
    nothing in a folder that no command claimed; on a write error, leaves the manifest as
    it was (a later --overwrite then refuses rather than guesses)."""
    folder = Path(folder)
    try:
        manifest = read_manifest(folder)
    except OutputFolderError:
        return
    if manifest is None:
        return
    listed = _with_folders(manifest.listed)
    existing = [e for e in entries(folder) if e in listed]
    try:
        _write_manifest(folder, existing, owner=False)
    except OutputFolderError:
        pass
