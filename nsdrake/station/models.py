"""Where nsdrake finds its model files (the repository's ``urdf/`` folder)."""

from __future__ import annotations

import sysconfig
from pathlib import Path

_PACKAGE_DIR = Path(__file__).resolve().parents[1]  # nsdrake/


def models_dir() -> Path:
    """The folder of shipped models: inside the installed package, or the repository's urdf/."""
    for candidate in (_PACKAGE_DIR / "urdf", _PACKAGE_DIR.parent / "urdf"):
        if candidate.is_dir():
            return candidate
    raise FileNotFoundError(f"nsdrake's urdf/ folder is missing (looked beside {_PACKAGE_DIR})")


PACKAGE_URI = "package://"


def installed_package(name: str) -> Path | None:
    """The folder of the ROS-style package ``name`` that pip installed through cmeel (as
    the ``example-robot-data`` package installs its robots: ``site-packages/cmeel.prefix/
    share/NAME``), or None."""
    folder = Path(sysconfig.get_paths()["purelib"]) / "cmeel.prefix" / "share" / name
    return folder if name and folder.is_dir() else None


def package_of(uri: str) -> str | None:
    """The package a ``package://NAME/...`` URI names, or None for a path."""
    return uri[len(PACKAGE_URI) :].partition("/")[0] if uri.startswith(PACKAGE_URI) else None


def resolve_model(name_or_path: str, base_dir: Path | None = None, packages=None) -> Path:
    """A model file: a path (absolute, or relative to ``base_dir``), the name of a shipped
    model, or ``package://NAME/path`` in the folder ``packages`` gives NAME (else the
    package pip installed: :func:`installed_package`).

    Raises FileNotFoundError naming every place it looked.
    """
    package = package_of(name_or_path)
    if package is not None:
        folder = (packages or {}).get(package) or installed_package(package)
        if folder is None:
            raise FileNotFoundError(
                f"model file '{name_or_path}': no package '{package}' (give its folder in arm.packages, "
                "or install the Python package that ships it)"
            )
        candidate = Path(folder) / name_or_path[len(PACKAGE_URI) + len(package) :].lstrip("/")
        if candidate.is_file():
            return candidate.resolve()
        raise FileNotFoundError(f"model file '{name_or_path}' not found (looked at {candidate})")
    path = Path(name_or_path).expanduser()
    candidates = [path] if path.is_absolute() else []
    if not path.is_absolute():
        if base_dir is not None:
            candidates.append(base_dir / path)
        candidates.append(Path.cwd() / path)
        candidates.append(models_dir() / path)
    for candidate in candidates:
        if candidate.is_file():
            return candidate.resolve()
    looked = ", ".join(str(c) for c in candidates)
    raise FileNotFoundError(f"model file '{name_or_path}' not found (looked at {looked})")
