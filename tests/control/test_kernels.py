"""The compiled kernels' housekeeping (nsdrake.control.kernels): one line while they
compile, and no stale machine code after a callee's source changes."""

from __future__ import annotations

from types import SimpleNamespace

from nsdrake.control.kernels import NOTICE, STAMP, _CompileNotice, refresh_cache


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


def test_a_changed_kernel_source_deletes_the_cached_kernels_once(tmp_path):
    """Catches a cache kept after a callee's file changed (numba watches only a kernel's
    own file), a cache deleted on every start (each run would compile again), and files
    other than nsdrake's cached kernels deleted."""
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
