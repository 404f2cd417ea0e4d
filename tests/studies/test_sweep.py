"""``nsdrake sweep``: spec checking, expansion, engines giving the same bytes, resume, failures.

Runs are 0.2 s of fig3 (before contact: the figures are the joint-speed ratio and the
time in each mode), three per sweep, so that the whole file stays around a minute.
"""

from __future__ import annotations

import csv
import io
import json
import shutil
import signal
import time

import numpy as np
import pytest
from conftest import copy_of_finished_run, once_per_test_run

from nsdrake.cli import main
from nsdrake.reporting.progress import Progress
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
    """The three-run sweep, simulated once in the whole test run (conftest's
    once_per_test_run), in process (--jobs 1): the bytes the other engines and a resumed
    sweep must reproduce. Tests read it or copy it, never change it."""

    def sweep(folder):
        spec = write_spec(folder)
        out = folder / "serial"
        assert main(["sweep", str(spec), "--out", str(out), "--jobs", "1"]) == 0
        return spec, out

    return once_per_test_run(tmp_path_factory, "sweep_reference", sweep)


# The reason of a 0.2 s fig3 run: it ends before the tool reaches the plate (at 1.27 s).
NO_CONTACT = (
    "no contact: the tool never pressed 0.5 N on the plate in the 0.2 s run, so the force figures are empty"
)


def table_rows(out) -> list[list[str]]:
    """results.csv's rows after the header, as CSV cells (a reason may hold commas)."""
    with (out / "results.csv").open(newline="") as f:
        return list(csv.reader(f))[1:]


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
    rows = table_rows(serial)
    assert [row[0] for row in rows] == ["0", "1", "2"]
    assert len({row[6] for row in rows}) == 3  # K_n changes the joint speeds
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
    assert table_rows(out)[2][1] == "150.0"
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


def test_overwrite_into_a_working_folder_removes_nothing(tmp_path, capsys, monkeypatch, finished_run):
    """Issue 15, item 1 (data loss): `nsdrake sweep --overwrite` into a working folder
    holding a user's file and an earlier `nsdrake run`'s runs/ deleted runs/ whole and
    exited 0. Catches any removal there: the folder is refused with one line, every byte
    survives, and no sweep file is written."""
    monkeypatch.chdir(tmp_path)
    copy_of_finished_run(finished_run, tmp_path / "runs" / "fig3")  # nsdrake run fig3's default folder
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


def test_overwrite_into_a_run_folder_with_a_users_file_removes_nothing(tmp_path, capsys, finished_run):
    """Catches a sweep that reclaims an `nsdrake run` folder while a file of the user's sits
    in it (the run's own files may go, but only when nothing else is there)."""
    out = copy_of_finished_run(finished_run, tmp_path / "run")
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
    status = {row[0]: (row[4], row[5]) for row in table_rows(out)}
    assert status["0"] == ("ok", NO_CONTACT)
    assert status["1"][0] == "failed" and status["1"][1].startswith("diverged at t = ")
    assert status["2"] == ("failed", "the worker process died (exit code 70)")
    assert "run 1 (divergence.max_torque=0.001, null_space.K_n=100.0) failed: diverged at t =" in err
    assert (out / "runs/0001/traces.csv").is_file()  # the traces up to the divergence
    monkeypatch.delenv(CRASH_ENV)
    assert main(["sweep", str(spec), "--out", str(out), "--jobs", "1"]) == 1
    assert "1 runs simulated, 2 already finished" in capsys.readouterr().out
    assert [row[4] for row in table_rows(out)] == ["ok", "failed", "ok"]
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
        bar = Progress("sweep", 4, unit="runs", stream=stream, width=8)
        bar(1)
        bar(4, failed=1)
    assert tty.getvalue() == "\r[##......] 1/4\r[########] 4/4 (1 failed)\n"
    assert log.getvalue() == ""  # no line before LOG_INTERVAL has passed


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


# --- hostile specs, sizes, schedulers, stored results (issue 15) ---------------------------

NOT_A_SPEC = {
    "a YAML list": (
        "spec.yaml",
        "- base: fig3\n- axes: {}\n",
        "the file: must be a mapping with description",
    ),
    "a number": ("spec.yaml", "42\n", "the file: must be a mapping with description"),
    "a JSON list": ("spec.json", '[{"base": "fig3"}]', "the file: must be a mapping with description"),
    "a JSON string": ("spec.json", '"fig3"', "the file: must be a mapping with description"),
    "base a list": (
        "spec.yaml",
        SPEC.replace("base: fig3", "base: [fig3]"),
        "base: unknown scenario ['fig3']",
    ),
    "axes a list": ("spec.yaml", _spec_with("axes: [null_space.K_n]\n"), "axes: must map at least one field"),
    "a metric that is a list": (
        "spec.yaml",
        _spec_with("metrics: [[force_error_rms]]\n"),
        "metrics[0]: unknown metric ['force_error_rms']; valid names are",
    ),
    "a field that is a list": ("spec.json", '{"base": "fig3", "x": 1, "axes": []}', "x: unknown field"),
}


@pytest.mark.parametrize("case", list(NOT_A_SPEC))
def test_a_spec_that_is_valid_yaml_or_json_but_not_a_mapping_is_one_line(tmp_path, monkeypatch, capsys, case):
    """Issue 15, item 5: valid YAML or JSON of the wrong shape (a list where a mapping or
    a name belongs) ended in a TypeError traceback. A .json spec is named by its file
    name alone too (no ./)."""
    name, text, expected = NOT_A_SPEC[case]
    (tmp_path / name).write_text(text)
    monkeypatch.chdir(tmp_path)
    assert main(["sweep", name, "--out", "out", "--jobs", "1"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith(f"nsdrake: error: {name}: ") and expected in err, err
    assert not (tmp_path / "out").exists()


def test_a_sweep_too_large_is_refused_before_any_run_is_listed_unless_max_runs(tmp_path, capsys):
    """Issue 15, item 4: a sweep of millions of runs started (and first spent hours
    checking each run's scenario) without a word. Its size is refused at once, naming the
    limit and how to raise it; random samples of 10^12 are refused without drawing them;
    with --max-runs raised the size passes (here the first run's scenario is then refused,
    the checks that come after the size)."""
    values = ", ".join(["-1.0"] + [f"{10.0 + k}" for k in range(39)])
    spec = write_spec(
        tmp_path, _spec_with(f"axes:\n  null_space.K_n: [{values}]\n  impedance.K_f: {[1.0] * 30}\n")
    )
    start = time.perf_counter()
    assert main(["sweep", str(spec), "--out", str(tmp_path / "out")]) == 2
    assert time.perf_counter() - start < 5
    assert capsys.readouterr().err == (
        f"nsdrake: error: {spec}: axes: 1200 runs (40 x 30) is more than --max-runs 1000 allows; "
        "pass --max-runs 1200 to run them all, or sweep fewer values\n"
    )
    assert main(["sweep", str(spec), "--out", str(tmp_path / "out"), "--max-runs", "1200"]) == 2
    captured = capsys.readouterr()
    assert captured.out == "nsdrake: sweep spec: 1200 runs (40 x 30); checking every run's scenario\n"
    assert "(run 0: null_space.K_n=-1.0, impedance.K_f=1.0): null_space.K_n: must be > 0" in captured.err
    huge = write_spec(
        tmp_path, _spec_with("axes:\n  null_space.K_n: {random: {low: 10, high: 50, count: 1000000000000}}\n")
    )
    start = time.perf_counter()
    assert main(["sweep", str(huge), "--max-runs", "5"]) == 2
    assert time.perf_counter() - start < 5
    assert "1000000000000 runs is more than --max-runs 5 allows" in capsys.readouterr().err
    assert not (tmp_path / "out").exists() and not (tmp_path / "runs").exists()


def test_the_size_is_stated_before_the_checks_and_sweeping_only_after_the_folder(tmp_path, capsys):
    """ "sweeping … into DIR/" is printed only once the folder is claimed: a refused folder
    gets the size line and the error, never "sweeping"."""
    spec = write_spec(tmp_path)
    (tmp_path / "out").mkdir()
    (tmp_path / "out" / "mine.txt").write_text("mine")
    assert main(["sweep", str(spec), "--out", str(tmp_path / "out"), "--jobs", "1"]) == 2
    captured = capsys.readouterr()
    assert captured.out == "nsdrake: sweep spec: 3 runs; checking every run's scenario\n"
    assert captured.err.count("\n") == 1 and "folder is not empty" in captured.err


@pytest.mark.parametrize(
    ("address", "expected"),
    [
        ("foo:bar:baz", "not a scheduler address (invalid address 'foo:bar:baz'"),
        ("http://127.0.0.1:8786", "not a scheduler address (unknown address scheme 'http'"),
        ("tcp://", "not a scheduler address (missing port number"),
    ],
)
def test_a_malformed_scheduler_address_is_one_line_before_anything_runs(tmp_path, capsys, address, expected):
    pytest.importorskip("dask.distributed", reason="Dask not installed: pip install 'nsdrake[cluster]'")
    spec = write_spec(tmp_path)
    out = tmp_path / "out"
    assert main(["sweep", str(spec), "--engine", "dask", "--scheduler", address, "--out", str(out)]) == 2
    captured = capsys.readouterr()
    assert captured.err.count("\n") == 1 and captured.err.startswith(
        f"nsdrake: error: --scheduler {address}: "
    )
    assert expected in captured.err and captured.out == "" and not out.exists()


def test_a_server_that_is_not_a_dask_scheduler_fails_within_the_connect_timeout(
    tmp_path, capsys, monkeypatch
):
    """Issue 15, item 5: a --scheduler address where a server of another kind listens (here
    a plain TCP server on 127.0.0.1 that accepts and says nothing) hung the sweep for ever,
    after claiming its folder: Dask's handshake has no time limit. Refused within the
    connect timeout, before the folder is made."""
    import socket
    import threading

    import nsdrake.studies.sweep_engines as engines

    pytest.importorskip("dask.distributed", reason="Dask not installed: pip install 'nsdrake[cluster]'")
    monkeypatch.setattr(engines, "CONNECT_TIMEOUT", 2.0)  # 10 s as shipped; the same code path
    server = socket.create_server(("127.0.0.1", 0))
    accepted = []
    thread = threading.Thread(target=lambda: accepted.append(server.accept()), daemon=True)
    thread.start()
    address = f"tcp://127.0.0.1:{server.getsockname()[1]}"
    spec, out = write_spec(tmp_path), tmp_path / "out"
    start = time.perf_counter()

    def hung(signum, frame):
        raise TimeoutError("the sweep still waits on the server after 60 s")

    previous = signal.signal(signal.SIGALRM, hung)
    signal.alarm(60)
    try:
        assert main(["sweep", str(spec), "--engine", "dask", "--scheduler", address, "--out", str(out)]) == 2
    finally:
        signal.alarm(0)
        signal.signal(signal.SIGALRM, previous)
        server.close()
    assert time.perf_counter() - start < 2.0 + 5
    assert accepted  # it did connect: the server, not the address, was wrong
    assert (
        capsys.readouterr().err
        == f"nsdrake: error: --scheduler {address}: no Dask scheduler answered within 2 s\n"
    )
    assert not out.exists()


def test_a_real_scheduler_answers_the_probe():
    """The probe itself: a Dask scheduler (an in-process LocalCluster's) is recognised."""
    pytest.importorskip("dask.distributed", reason="Dask not installed: pip install 'nsdrake[cluster]'")
    from dask.distributed import LocalCluster

    from nsdrake.studies.sweep_engines import check_scheduler

    with LocalCluster(n_workers=0, processes=False, dashboard_address=None) as cluster:
        assert check_scheduler(cluster.scheduler_address, 10.0)["type"] == "Scheduler"


@pytest.mark.parametrize(
    "damage",
    ["a field missing", "a list, not a mapping", "a field of another type", "cut short", "traces gone"],
)
def test_a_resumed_sweep_runs_again_a_run_whose_stored_result_is_incomplete(
    reference, tmp_path, capsys, damage
):
    """Issue 15, item 5: a result.json without its "status" (a file edited, restored from a
    half backup) ended the resumed sweep in a KeyError traceback. Such a run is run again,
    and the table has the bytes of an undamaged sweep."""
    spec, serial = reference
    out = tmp_path / "resumed"
    shutil.copytree(serial, out)
    result = out / "runs/0001/result.json"
    record = json.loads(result.read_text())
    if damage == "a field missing":
        del record["status"]
        result.write_text(json.dumps(record))
    elif damage == "a list, not a mapping":
        result.write_text(json.dumps([record]))
    elif damage == "a field of another type":
        record["values"] = list(record["values"].items())
        result.write_text(json.dumps(record))
    elif damage == "cut short":
        result.write_text(result.read_text()[:40])
    else:
        (out / "runs/0001/traces.csv").unlink()
    capsys.readouterr()
    assert main(["sweep", str(spec), "--out", str(out), "--jobs", "1"]) == 0
    assert "1 runs simulated, 2 already finished (resumed)" in capsys.readouterr().out
    assert (out / "results.csv").read_bytes() == (serial / "results.csv").read_bytes()
    assert run_files(out) == run_files(serial)


def test_runs_that_never_reach_contact_say_why_in_the_row_and_at_the_end(reference, tmp_path, capsys):
    """Issue 15, item 9: the 0.2 s runs end before contact; their force figures were empty
    and all_bounds_met false without a word. Each row's reason says why, and so does a
    line at the end."""
    spec, serial = reference
    assert [row[4] for row in table_rows(serial)] == [NO_CONTACT] * 3
    assert [row[8] for row in table_rows(serial)] == ["false"] * 3
    out = tmp_path / "again"
    shutil.copytree(serial, out)
    capsys.readouterr()
    assert main(["sweep", str(spec), "--out", str(out), "--jobs", "1"]) == 0
    assert f"nsdrake: 3 of 3 runs have empty force figures (all_bounds_met false); run 0: {NO_CONTACT}" in (
        capsys.readouterr().out
    )
