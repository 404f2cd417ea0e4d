"""Where nsdrake finds its model files (the repository's ``urdf/`` folder)."""

from __future__ import annotations

from pathlib import Path

_PACKAGE_DIR = Path(__file__).resolve().parents[1]  # nsdrake/


def models_dir() -> Path:
    """The folder of shipped models: inside the installed package, or the repository's urdf/."""
    for candidate in (_PACKAGE_DIR / "urdf", _PACKAGE_DIR.parent / "urdf"):
        if candidate.is_dir():
            return candidate
    raise FileNotFoundError(f"nsdrake's urdf/ folder is missing (looked beside {_PACKAGE_DIR})")


def resolve_model(name_or_path: str, base_dir: Path | None = None) -> Path:
    """A model file: a path (absolute, or relative to ``base_dir``), or the name of a shipped model.

    Raises FileNotFoundError naming every place it looked.
    """
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
