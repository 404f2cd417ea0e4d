"""``nsdrake sweep``: spec checking, expansion, engines giving the same bytes, resume, failures.

Runs are 0.2 s of fig3 (before contact: the figures are the joint-speed ratio and the
time in each mode), three per sweep, so that the whole file stays around a minute.
"""

from __future__ import annotations

import io
import json
import shutil
import time

import numpy as np
import pytest

from nsdrake.cli import main
from nsdrake.studies.sweep import SweepProgress
from nsdrake.studies.sweep_spec import METRICS, expand, load_sweep
from nsdrake.studies.sweep_worker import CRASH_ENV

SPEC = """\
base: fig3
duration: 0.2
seed: 7
axes:
  null_space.K_n: [50.0, 100.0, 200.0]
metrics: [first_contact_time, joint_speed_ratio_max, mode2_time, all_bounds_met]
"""


def write_spec(folder, text=SPEC, name="spec.yaml"):
    path = folder / name
    path.write_text(text)
    return path


@pytest.fixture(scope="module")
def reference(tmp_path_factory):
    """The three-run sweep, simulated once in this process (--jobs 1): the bytes the
    other engines and a resumed sweep must reproduce."""
    folder = tmp_path_factory.mktemp("sweep")
    spec = write_spec(folder)
    out = folder / "serial"
    assert main(["sweep", str(spec), "--out", str(out), "--jobs", "1"]) == 0
    return spec, out


def run_files(out):
    return {
        p.relative_to(out).as_posix(): p.read_bytes() for p in sorted((out / "runs").glob("*/traces.csv"))
    }


# --- the spec ------------------------------------------------------------------------


BAD_SPECS = {
    "unknown top-level field": ("axis:\n  null_space.K_n: [1.0]\n", "axis: unknown field"),
    "unknown field path": (
        "axes:\n  null_space.K_x: [1.0]\n",
        "axes.null_space.K_x: unknown field 'K_x'; valid fields of null_space are K_n,",
    ),
    "path through a number": (
        "axes:\n  null_space.K_n.low: [1.0]\n",
        "axes.null_space.K_n.low: null_space.K_n is a number, it has no field 'low'",
    ),
    "value of the wrong type": (
        "axes:\n  null_space.K_n: [50.0, fast]\n",
        "axes.null_space.K_n[1]: must be a number, got 'fast'",
    ),
    "empty axis": ("axes:\n  null_space.K_n: []\n", "axes.null_space.K_n: empty axis"),
    "no axes": ("axes: {}\n", "axes: must map at least one field path"),
    "random on a non-number": (
        "axes:\n  null_space.pseudo_inverse: {random: {low: 0, high: 1, count: 2}}\n",
        "axes.null_space.pseudo_inverse.random: random samples need a number field",
    ),
    "random with high <= low": (
        "axes:\n  null_space.K_n: {random: {low: 50, high: 10, count: 2}}\n",
        "axes.null_space.K_n.random.high: must be a number above low = 50",
    ),
    "random counts differ": (
        "axes:\n  null_space.K_n: {random: {low: 10, high: 50, count: 2}}\n"
        "  impedance.K_f: {random: {low: 0.5, high: 2, count: 3}}\n",
        "axes: the random axes are sampled together and must share one count, got 2, 3",
    ),
    "a run's scenario invalid": (
        "axes:\n  null_space.K_n: [50.0, -1.0]\n",
        "(run 1: null_space.K_n=-1.0): null_space.K_n: must be > 0, got -1.0",
    ),
    "a run the model checks refuse": (
        "axes:\n  null_space.K_n: [50.0, 2000.0]\n",
        "(run 1: null_space.K_n=2000.0): null_space.K_n:",
    ),
    "unknown metric": ("metrics: [force_rms]\n", "metrics[0]: unknown metric 'force_rms'; valid names are"),
    "unknown base": ("base: fig4\n", "base: unknown scenario 'fig4'; the shipped scenarios are"),
    "bad seed": ("seed: -3\n", "seed: must be a whole number >= 0, got -3"),
}


def _spec_with(change: str) -> str:
    """SPEC with one top-level field replaced by ``change`` (or ``change`` added)."""
    key = change.split(":", 1)[0]
    lines, skipping = [], False
    for line in SPEC.splitlines(keepends=True):
        if line.startswith(f"{key}:"):
            skipping = True
            continue
        if skipping and line.startswith(" "):
            continue
        skipping = False
        lines.append(line)
    return "".join(lines) + change


@pytest.mark.parametrize("case", list(BAD_SPECS))
def test_every_bad_spec_is_one_line_naming_the_file_and_field_before_anything_runs(tmp_path, capsys, case):
    """Catches a spec mistake that starts runs (or makes the output folder) before it is
    refused, a traceback or several lines instead of one, and a message that does not
    say which field of which file is wrong."""
    change, expected = BAD_SPECS[case]
    spec = write_spec(tmp_path, _spec_with(change))
    out = tmp_path / "out"
    code = main(["sweep", str(spec), "--out", str(out), "--jobs", "1"])
    err = capsys.readouterr().err
    assert code == 2, err
    assert err.count("\n") == 1 and err.startswith(f"nsdrake: error: {spec}"), err
    assert expected in err, err
    assert not out.exists()


def test_a_missing_dask_or_a_scheduler_without_dask_is_one_line(tmp_path, capsys, monkeypatch):
    """Catches a raw ImportError traceback when Dask is not installed (the message must
    name the extra to install), and --scheduler silently ignored by the process engine."""
    import builtins

    spec = write_spec(tmp_path)
    assert main(["sweep", str(spec), "--scheduler", "tcp://127.0.0.1:1"]) == 2
    assert capsys.readouterr().err == "nsdrake: error: --scheduler needs --engine dask\n"
    real_import = builtins.__import__

    def no_dask(name, *args, **kwargs):
        if name.startswith(("dask", "distributed")):
            raise ImportError(f"No module named '{name}'")
        return real_import(name, *args, **kwargs)

    monkeypatch.setattr(builtins, "__import__", no_dask)
    assert main(["sweep", str(spec), "--engine", "dask", "--out", str(tmp_path / "o")]) == 2
    assert capsys.readouterr().err == (
        "nsdrake: error: --engine dask needs Dask: pip install 'nsdrake[cluster]'\n"
    )


def test_the_shipped_sweep_loads_and_every_run_passes_the_checks(capsys):
    """Catches a shipped sweep broken by a renamed field or metric, or with a run the
    checks refuse; and `nsdrake list` not showing the sweeps."""
    from nsdrake.studies.sweep_spec import plan_runs

    spec = load_sweep("robustness")
    assert len(plan_runs(spec)) == 18
    assert main(["list"]) == 0
    assert "sweeps (nsdrake sweep):    robustness" in capsys.readouterr().out


# --- expansion -----------------------------------------------------------------------


def test_grid_is_the_product_in_axis_order_and_random_samples_follow_the_seed(tmp_path):
    """Catches a grid that is zipped instead of multiplied or ordered differently from
    the spec, random samples outside [low, high] or drawn independently of the seed
    (a resumed sweep would then see different runs), and random axes sampled on a grid
    instead of jointly."""
    grid = load_sweep(
        str(
            write_spec(
                tmp_path,
                _spec_with("axes:\n  null_space.K_n: [1.0, 2.0]\n  impedance.K_f: [3.0, 4.0, 5.0]\n"),
            )
        )
    )
    assert expand(grid) == [
        {"null_space.K_n": k, "impedance.K_f": f} for k in (1.0, 2.0) for f in (3.0, 4.0, 5.0)
    ]
    random_axes = (
        "axes:\n  null_space.K_n: [1.0, 2.0]\n"
        "  impedance.K_f: {random: {low: 0.5, high: 2.0, count: 4}}\n"
        "  reference.force: {random: {low: 5.0, high: 15.0, count: 4}}\n"
    )
    a = expand(load_sweep(str(write_spec(tmp_path, _spec_with(random_axes), "a.yaml"))))
    b = expand(load_sweep(str(write_spec(tmp_path, _spec_with(random_axes), "b.yaml"))))
    c = expand(
        load_sweep(str(write_spec(tmp_path, _spec_with(random_axes).replace("seed: 7", "seed: 8"), "c.yaml")))
    )
    assert a == b and a != c
    assert len(a) == 8 and [r["null_space.K_n"] for r in a] == [1.0] * 4 + [2.0] * 4
    points = [(r["impedance.K_f"], r["reference.force"]) for r in a]
    assert points[:4] == points[4:]  # the same random points inside every grid cell
    assert len(set(points[:4])) == 4  # jointly drawn: four distinct points, not a 4 x 4 grid
    f, force = np.array(points).T
    assert np.all((0.5 <= f) & (f < 2.0)) and np.all((5.0 <= force) & (force < 15.0))


# --- engines -------------------------------------------------------------------------


def test_two_processes_write_the_same_bytes_as_one(reference, tmp_path):
    """Catches rows written in completion order, floats formatted with platform- or
    order-dependent precision, and a worker that simulates a different scenario than the
    serial path (e.g. lost overrides or seed when the task is pickled)."""
    spec, serial = reference
    out = tmp_path / "parallel"
    assert main(["sweep", str(spec), "--out", str(out), "--jobs", "2"]) == 0
    assert (out / "results.csv").read_bytes() == (serial / "results.csv").read_bytes()
    assert run_files(out) == run_files(serial)
    lines = (serial / "results.csv").read_text().splitlines()
    assert lines[0] == (
        "index,null_space.K_n,seed,status,reason,first_contact_time,joint_speed_ratio_max,mode2_time,all_bounds_met"
    )
    assert [line.split(",")[0] for line in lines[1:]] == ["0", "1", "2"]
    assert len({line.split(",")[6] for line in lines[1:]}) == 3  # K_n changes the joint speeds
    assert (out / "sweep.png").stat().st_size > 0


def test_dask_local_cluster_writes_the_same_bytes(reference, tmp_path):
    """Catches a Dask engine whose results differ from the process pool's (tasks that
    carry Drake objects, results in completion order), or that leaves its cluster up."""
    pytest.importorskip("dask.distributed", reason="Dask not installed: pip install 'nsdrake[cluster]'")
    spec, serial = reference
    out = tmp_path / "dask"
    assert main(["sweep", str(spec), "--out", str(out), "--engine", "dask", "--jobs", "2"]) == 0
    assert (out / "results.csv").read_bytes() == (serial / "results.csv").read_bytes()
    assert run_files(out) == run_files(serial)


# --- resume --------------------------------------------------------------------------


def test_resume_simulates_only_the_missing_run_and_rebuilds_the_same_table(reference, tmp_path, capsys):
    """Catches a resumed sweep that re-simulates finished runs (or overwrites their
    traces), one that skips the missing run, and a table rebuilt differently."""
    spec, serial = reference
    out = tmp_path / "resumed"
    shutil.copytree(serial, out)
    (out / "runs/0001/result.json").unlink()
    (out / "results.csv").unlink()
    before = {i: (out / f"runs/000{i}/traces.csv").stat().st_mtime_ns for i in range(3)}
    time.sleep(0.01)
    capsys.readouterr()
    assert main(["sweep", str(spec), "--out", str(out), "--jobs", "1"]) == 0
    assert "1 runs simulated, 2 already finished (resumed)" in capsys.readouterr().out
    after = {i: (out / f"runs/000{i}/traces.csv").stat().st_mtime_ns for i in range(3)}
    assert after[0] == before[0] and after[2] == before[2] and after[1] > before[1]
    assert (out / "results.csv").read_bytes() == (serial / "results.csv").read_bytes()
    assert run_files(out) == run_files(serial)


def test_a_sweep_killed_mid_run_resumes_and_loses_nothing(reference, tmp_path):
    """Catches a kill (SIGKILL: no clean-up runs) leaving a half-written result.json or
    traces.csv that a resumed sweep trusts, or a finished run lost: resumed, the table
    has the bytes of an uninterrupted sweep."""
    import os
    import signal
    import subprocess
    import sys

    spec, serial = reference
    out = tmp_path / "killed"
    command = [sys.executable, "-m", "nsdrake.cli", "sweep", str(spec), "--out", str(out), "--jobs", "1"]
    process = subprocess.Popen(command, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    deadline = time.monotonic() + 120
    while not (out / "runs/0000/result.json").exists() and process.poll() is None:
        assert time.monotonic() < deadline
        time.sleep(0.02)
    os.kill(process.pid, signal.SIGKILL)
    process.wait()
    assert main(["sweep", str(spec), "--out", str(out), "--jobs", "1"]) == 0
    assert (out / "results.csv").read_bytes() == (serial / "results.csv").read_bytes()
    assert run_files(out) == run_files(serial)


def test_a_changed_spec_is_refused_in_the_old_folder_unless_overwrite(reference, tmp_path, capsys):
    """Catches a changed spec silently mixing its runs with the old ones in one table, or
    replacing them without --overwrite; and --overwrite re-simulating runs that did not
    change."""
    spec, serial = reference
    out = tmp_path / "changed"
    shutil.copytree(serial, out)
    changed = write_spec(tmp_path, SPEC.replace("200.0", "150.0"), "changed.yaml")
    assert main(["sweep", str(changed), "--out", str(out), "--jobs", "1"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and f"nsdrake: error: {out}: holds a sweep of {spec}" in err
    assert "pass --overwrite" in err
    assert (out / "results.csv").read_bytes() == (serial / "results.csv").read_bytes()
    assert main(["sweep", str(changed), "--out", str(out), "--jobs", "1", "--overwrite"]) == 0
    assert "1 runs simulated, 2 already finished" in capsys.readouterr().out
    assert (out / "results.csv").read_text().splitlines()[3].split(",")[1] == "150.0"
    assert main(["sweep", str(spec), "--out", str(tmp_path / "elsewhere"), "--jobs", "1"]) == 0
    assert (tmp_path / "elsewhere/results.csv").read_bytes() == (serial / "results.csv").read_bytes()


def test_a_non_sweep_folder_is_never_written_into_without_overwrite(tmp_path, capsys):
    """Catches a sweep writing into (or resuming from) a folder that holds the user's files."""
    out = tmp_path / "mine"
    out.mkdir()
    (out / "notes.txt").write_text("mine")
    spec = write_spec(tmp_path)
    assert main(["sweep", str(spec), "--out", str(out), "--jobs", "1"]) == 2
    assert "folder is not empty" in capsys.readouterr().err
    assert sorted(p.name for p in out.iterdir()) == ["notes.txt"]


def _tree(folder):
    """Every file below ``folder`` with its bytes (the manifest aside)."""
    return {
        p.relative_to(folder).as_posix(): p.read_bytes()
        for p in sorted(folder.rglob("*"))
        if p.is_file() and not p.name.startswith(".nsdrake-run")
    }


def test_overwrite_into_a_working_folder_removes_nothing(tmp_path, capsys, monkeypatch):
    """Issue 15, item 1 (data loss): `nsdrake sweep --overwrite` into a working folder
    holding a user's file and an earlier `nsdrake run`'s runs/ deleted runs/ whole and
    exited 0. Catches any removal there: the folder is refused with one line, every byte
    survives, and no sweep file is written."""
    monkeypatch.chdir(tmp_path)
    assert main(["run", "fig3", "--duration", "0.1", "--no-replay"]) in (0, 1)
    (tmp_path / "notes.txt").write_text("mine")
    spec = write_spec(tmp_path)
    before = _tree(tmp_path)
    capsys.readouterr()
    assert main(["sweep", str(spec), "--out", ".", "--jobs", "1", "--overwrite"]) == 2
    captured = capsys.readouterr()
    assert captured.err.count("\n") == 1 and "--overwrite refused" in captured.err, captured.err
    assert "sweeping" not in captured.out  # refused before it said it would sweep
    assert _tree(tmp_path) == before
    assert not (tmp_path / "sweep.json").exists()


def test_overwrite_into_a_run_folder_with_a_users_file_removes_nothing(tmp_path, capsys):
    """Catches a sweep that reclaims an `nsdrake run` folder while a file of the user's sits
    in it (the run's own files may go, but only when nothing else is there)."""
    out = tmp_path / "run"
    assert main(["run", "fig3", "--duration", "0.1", "--no-replay", "--out", str(out)]) in (0, 1)
    (out / "mine.txt").write_text("mine")
    before = _tree(out)
    spec = write_spec(tmp_path)
    capsys.readouterr()
    assert main(["sweep", str(spec), "--out", str(out), "--jobs", "1", "--overwrite"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "nsdrake did not write mine.txt" in err, err
    assert _tree(out) == before


def test_overwrite_of_another_sweep_removes_only_its_listed_runs(reference, tmp_path, capsys):
    """Catches --overwrite deleting a user's file inside another sweep's folder (refused,
    nothing removed) and, without one, removing more than the runs the new spec drops
    (a run folder holding only the old sweep's files)."""
    spec, serial = reference
    out = tmp_path / "other"
    shutil.copytree(serial, out)
    (out / "runs/0002/notes.txt").write_text("mine")
    shorter = write_spec(tmp_path, SPEC.replace("[50.0, 100.0, 200.0]", "[50.0, 100.0]"), "short.yaml")
    before = _tree(out)
    capsys.readouterr()
    assert main(["sweep", str(shorter), "--out", str(out), "--jobs", "1", "--overwrite"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "nsdrake did not write runs/0002/notes.txt" in err, err
    assert _tree(out) == before
    (out / "runs/0002/notes.txt").unlink()
    assert main(["sweep", str(shorter), "--out", str(out), "--jobs", "1", "--overwrite"]) == 0
    assert sorted(p.name for p in (out / "runs").iterdir()) == ["0000", "0001"]
    assert (out / "runs/0000/traces.csv").read_bytes() == (serial / "runs/0000/traces.csv").read_bytes()


def test_a_folder_claimed_by_a_live_process_is_refused(reference, tmp_path, capsys):
    """Catches a sweep resuming (or replacing) a folder while another nsdrake process is
    still writing into it: two writers would interleave their results."""
    import subprocess
    import sys

    spec, serial = reference
    out = tmp_path / "busy"
    shutil.copytree(serial, out)
    sleeper = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(60)"])
    try:
        from nsdrake.experiment.output import _start_time

        manifest = (out / ".nsdrake-run").read_text()
        import socket

        owner = f"# owner: {socket.gethostname()} {sleeper.pid} {_start_time(sleeper.pid)}\n"
        (out / ".nsdrake-run").write_text(manifest + owner)
        before = _tree(out)
        assert main(["sweep", str(spec), "--out", str(out), "--jobs", "1"]) == 2
        err = capsys.readouterr().err
        assert err.count("\n") == 1 and f"nsdrake process {sleeper.pid} is still writing" in err, err
        assert _tree(out) == before
    finally:
        sleeper.kill()
        sleeper.wait()
    # its process gone, the claim is stale: the sweep resumes (nothing to simulate)
    assert main(["sweep", str(spec), "--out", str(out), "--jobs", "1"]) == 0
    assert "0 runs simulated, 3 already finished" in capsys.readouterr().out


# --- failures ------------------------------------------------------------------------


def test_a_failing_run_and_a_dying_worker_are_rows_and_the_exit_status_is_1(tmp_path, capsys, monkeypatch):
    """Catches a run that raises (here: diverges at once, its torque bound set below any
    torque) ending the sweep, a worker process that dies hanging the pool or failing the
    other runs, a non-zero exit status lost; and, on resume, a crashed run not retried
    or a deterministic failure re-simulated."""
    spec = write_spec(
        tmp_path,
        _spec_with("axes:\n  divergence.max_torque: [10000.0, 0.001, 10000.0]\n  null_space.K_n: [100.0]\n"),
    )
    out = tmp_path / "out"
    monkeypatch.setenv(CRASH_ENV, "2")  # the worker process that gets run 2 exits
    assert main(["sweep", str(spec), "--out", str(out), "--jobs", "2"]) == 1
    err = capsys.readouterr().err
    rows = [line.split(",") for line in (out / "results.csv").read_text().splitlines()[1:]]
    status = {row[0]: (row[4], row[5]) for row in rows}
    assert status["0"] == ("ok", "")
    assert status["1"][0] == "failed" and status["1"][1].startswith("diverged at t = ")
    assert status["2"] == ("failed", "the worker process died (exit code 70)")
    assert "run 1 (divergence.max_torque=0.001, null_space.K_n=100.0) failed: diverged at t =" in err
    assert (out / "runs/0001/traces.csv").is_file()  # the traces up to the divergence
    monkeypatch.delenv(CRASH_ENV)
    assert main(["sweep", str(spec), "--out", str(out), "--jobs", "1"]) == 1
    assert "1 runs simulated, 2 already finished" in capsys.readouterr().out
    rows = [line.split(",") for line in (out / "results.csv").read_text().splitlines()[1:]]
    assert [row[4] for row in rows] == ["ok", "failed", "ok"]
    assert json.loads((out / "runs/0002/result.json").read_text())["crashed"] is False


# --- progress and metric names -------------------------------------------------------


def test_the_progress_bar_is_drawn_on_a_terminal_only():
    """Catches progress text written into CI logs (not a terminal), and a bar that
    does not count runs."""

    class Terminal(io.StringIO):
        def isatty(self):
            return True

    tty, log = Terminal(), io.StringIO()
    for stream in (tty, log):
        bar = SweepProgress(4, stream=stream, width=8)
        bar(1)
        bar(4, failed=1)
    assert tty.getvalue() == "\r[##......] 1/4\r[########] 4/4 (1 failed)\n"
    assert log.getvalue() == ""


def test_metric_names_are_those_nsdrake_run_computes(tmp_path):
    """Catches the sweep's list of metric names drifting from runner.compute_metrics
    (a renamed figure would be refused, or silently collected as empty cells)."""
    from nsdrake.experiment.scenario import load_scenario
    from nsdrake.experiment.simulate import run
    from nsdrake.experiment.traces import Traces
    from nsdrake.reporting.run_folder import compute_metrics

    scenario = load_scenario("fig3", duration=0.6)
    traces, built = run(scenario)
    columns = {name: traces[name] for name in traces.names}
    columns["f_n"] = columns["f_d"] = np.full(len(traces), 10.0)  # pressing from t = 0
    pressing = Traces(columns)
    names = {m.name for m in compute_metrics(scenario, built.station, pressing, pressing)}
    assert names <= set(METRICS)
    assert {name for name, check in METRICS.items() if check == "fig3"} <= names
