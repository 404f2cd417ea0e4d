"""The command line: files written, folders never overwritten without asking, errors."""

from __future__ import annotations

import json
import re
import subprocess
import sys

import pytest

from nsdrake.cli import _Progress, main
from nsdrake.traces import Traces

REQUIRED_COLUMNS = (
    "t x y x_d y_d f_x f_y f_d q1 q2 q3 q4 v1 v2 v3 v4 tau1 tau2 tau3 tau4 "
    "qns1 qns2 qns3 qns4 en1 en2 en3 en4 nu"
).split()


def test_run_writes_traces_plot_and_metrics(tmp_path, capsys):
    out = tmp_path / "run"
    code = main(["run", "fig3", "--duration", "0.3", "--out", str(out)])
    assert code in (0, 1)  # 0.3 s ends before contact: the contact figures fail honestly
    for name in ("traces.csv", "fig3.png", "metrics.json", "scenario.yaml", "diagram.dot", "replay.html"):
        assert (out / name).is_file(), name
    assert (out / "report.html").is_file()
    traces = Traces.read_csv(out / "traces.csv")
    assert [c for c in REQUIRED_COLUMNS if c not in traces] == []
    assert len(traces) == 151  # t = 0, 0.002, …, 0.3
    metrics = json.loads((out / "metrics.json").read_text())
    assert "first_contact_time" in metrics["metrics"]
    printed = capsys.readouterr().out
    assert str(out) in printed
    assert f"open {out / 'report.html'} in a browser" in printed


def test_no_replay_writes_everything_but_the_replay(tmp_path):
    out = tmp_path / "run"
    assert main(["run", "fig3", "--duration", "0.1", "--out", str(out), "--no-replay"]) in (0, 1)
    assert not (out / "replay.html").exists()
    assert (out / "report.html").is_file() and (out / "diagram.dot").is_file()
    assert "replay.html" not in (out / "report.html").read_text()


def test_meshcat_flag_prints_a_localhost_url(tmp_path, capsys):
    """Not on a terminal (as here): no waiting for a browser, no prompt at the end."""
    out = tmp_path / "run"
    assert main(["run", "fig3", "--duration", "0.2", "--out", str(out), "--meshcat"]) in (0, 1)
    printed = capsys.readouterr().out
    assert re.search(r"Meshcat is at http://localhost:\d+", printed), printed
    assert (out / "replay.html").is_file()


@pytest.mark.parametrize("tty", [False, True])
def test_progress_bar_only_on_a_terminal(monkeypatch, capsys, tty):
    monkeypatch.setattr(sys.stderr, "isatty", lambda: tty, raising=False)
    progress = _Progress("fig3")
    for k in range(5):
        progress(k / 4)
    err = capsys.readouterr().err
    if tty:
        assert err.count("\r") == 5 and "100%" in err and err.endswith("\n")
    else:
        assert err == ""


def test_written_scenario_reloads_to_the_same_run(tmp_path):
    from nsdrake.scenario import load_scenario, load_scenario_file

    out = tmp_path / "run"
    main(["run", "fig3", "--duration", "0.2", "--out", str(out)])
    again = load_scenario_file(out / "scenario.yaml")
    original = load_scenario("fig3", duration=0.2)
    assert again.impedance == original.impedance and again.arm == original.arm
    assert again.duration == 0.2


def test_non_empty_output_folder_is_refused_without_overwrite(tmp_path, capsys):
    out = tmp_path / "mine"
    out.mkdir()
    (out / "notes.txt").write_text("keep me")
    assert main(["run", "fig3", "--duration", "0.1", "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "not empty" in err
    assert (out / "notes.txt").read_text() == "keep me"
    assert not (out / "traces.csv").exists()
    assert main(["run", "fig3", "--duration", "0.1", "--out", str(out), "--overwrite"]) in (0, 1)
    assert (out / "traces.csv").exists() and (out / "notes.txt").read_text() == "keep me"


def test_default_output_folder_never_overwrites(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    main(["run", "fig3", "--duration", "0.1"])
    main(["run", "fig3", "--duration", "0.1"])
    assert (tmp_path / "runs" / "fig3" / "traces.csv").exists()
    assert (tmp_path / "runs" / "fig3-2" / "traces.csv").exists()


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["run", "fig4"], "unknown scenario 'fig4'"),
        (["run", "fig3", "--duration", "0"], "--duration must be > 0"),
        (["run", "fig3", "--duration", "nan"], "--duration must be > 0"),
        (["run", "fig3", "--duration", "soon"], "--duration must be a number"),
        (["run", "fig3", "--config", "absent.yaml"], "absent.yaml: no such scenario file"),
        (["run", "fig3", "--bogus"], "unrecognized arguments: --bogus"),
        (["walk"], "invalid choice: 'walk'"),
    ],
)
def test_bad_command_lines_fail_with_one_line(tmp_path, monkeypatch, capsys, args, message):
    monkeypatch.chdir(tmp_path)
    assert exit_code(args) == 2
    err = capsys.readouterr().err
    assert message in err and err.count("\n") == 1
    assert not (tmp_path / "runs").exists()  # nothing was started


def test_bad_config_fails_before_the_output_folder_is_made(tmp_path, capsys):
    config = tmp_path / "bad.yaml"
    config.write_text("arm: {initial_positions: {joint9: 0.3}}\n")
    out = tmp_path / "out"
    assert main(["run", "fig3", "--config", str(config), "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert "arm.initial_positions.joint9: unknown joint" in err and err.count("\n") == 1
    assert not out.exists()


def test_console_script_exit_status(tmp_path):
    """The installed entry point, as a user runs it."""
    result = subprocess.run(
        [sys.executable, "-m", "nsdrake.cli", "run", "fig3", "--config", str(tmp_path / "x.yaml")],
        capture_output=True,
        text=True,
        cwd=tmp_path,
    )
    assert result.returncode == 2
    assert result.stderr.strip().startswith("nsdrake: error:") and result.stderr.count("\n") == 1


def exit_code(args) -> int:
    """main()'s status, whether it returns it or argparse exits with it."""
    try:
        return main(args)
    except SystemExit as e:
        return e.code
