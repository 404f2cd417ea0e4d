"""The compiled kernels' housekeeping (nsdrake.control.kernels): one line while they
compile, and no stale machine code after a callee's source changes."""

from __future__ import annotations

from types import SimpleNamespace

from numba.core import config

from nsdrake.control.kernels import NOTICE, STAMP, _CompileNotice, cache_folder, refresh_cache


def _event(module: str):
    return SimpleNamespace(data={"dispatcher": SimpleNamespace(py_func=SimpleNamespace(__module__=module))})


def test_the_notice_is_one_line_for_the_first_nsdrake_kernel(capsys):
    """Catches a line per kernel (a first run compiles about 170), a line for other
    packages' kernels, and no line at all."""
    notice = _CompileNotice()
    notice.on_start(_event("numba.np.arrayobj"))
    assert capsys.readouterr().err == ""
    for module in ("nsdrake.control.stages", "nsdrake.control.priority", "nsdrake.station.force_sensor"):
        notice.on_start(_event(module))
    assert capsys.readouterr().err == NOTICE + "\n"


def test_a_changed_kernel_source_deletes_the_cached_kernels_once(tmp_path, monkeypatch):
    """Catches a cache kept after a callee's file changed (numba watches only a kernel's
    own file), a cache deleted on every start (each run would compile again), and files
    other than nsdrake's cached kernels deleted."""
    monkeypatch.setattr(config, "CACHE_DIR", "")  # numba's default: __pycache__ beside the source
    package = tmp_path / "nsdrake"
    (package / "control" / "__pycache__").mkdir(parents=True)
    source = package / "control" / "stages.py"
    source.write_text("@njit(cache=True)\ndef f(x):\n    return x\n")
    (package / "control" / "plain.py").write_text("def g():\n    pass\n")
    cached = [package / "control" / "__pycache__" / f"stages.f-2.py311.{k}" for k in ("nbi", "1.nbc")]
    other = package / "control" / "__pycache__" / "stages.cpython-311.pyc"

    def fill():
        for path in (*cached, other):
            path.write_bytes(b"x")

    fill()
    assert refresh_cache(package)  # no stamp yet: compiled by an unknown version
    assert not any(p.exists() for p in cached) and other.exists()
    assert (package / "__pycache__" / STAMP).is_file()
    fill()
    assert not refresh_cache(package)  # unchanged: loads
    assert all(p.exists() for p in cached)
    source.write_text(source.read_text() + "\n# edited\n")
    assert refresh_cache(package)
    assert not any(p.exists() for p in cached) and other.exists()


def test_with_numba_cache_dir_the_stamp_and_the_deletions_are_there(tmp_path, monkeypatch):
    """NUMBA_CACHE_DIR moves numba's cache (a test's cold cache, a read-only install): the
    check must stamp and clean that cache. Catches a stamp written beside the sources by a
    run whose kernels live elsewhere, which vouched for a default cache compiled from older
    sources (they then ran stale), and the moved cache never cleaned."""
    package = tmp_path / "nsdrake"
    (package / "control").mkdir(parents=True)
    (package / "__init__.py").write_text("")
    source = package / "control" / "stages.py"
    source.write_text("@njit(cache=True)\ndef f(x):\n    return x\n")
    monkeypatch.setattr(config, "CACHE_DIR", str(tmp_path / "cache"))
    moved = cache_folder(source)
    moved.mkdir(parents=True)
    cached = moved / "stages.f-2.py311.nbi"
    cached.write_bytes(b"x")
    assert refresh_cache(package) and not cached.exists()
    assert not (package / "__pycache__").exists()  # nothing stamped beside the sources
    cached.write_bytes(b"x")
    assert not refresh_cache(package) and cached.exists()
    source.write_text(source.read_text() + "\n# edited\n")
    assert refresh_cache(package) and not cached.exists()
