"""nsdrake drive and nsdrake sim-driver on the command line (memq:// only)."""

from __future__ import annotations

import json
import subprocess
import sys
import time

import numpy as np
import pytest
from conftest import without_notices
from drake import lcmt_panda_command, lcmt_panda_status
from pydrake.lcm import DrakeLcm

from nsdrake.cli import main
from nsdrake.driver.run import serve_simulated_driver
from nsdrake.experiment.scenario import load_scenario
from nsdrake.experiment.traces import Traces


def exit_code(argv) -> int:
    """main's exit status, whether it returns it or argparse exits."""
    try:
        return main(argv)
    except SystemExit as e:
        return e.code


def test_nobody_publishing_ends_with_one_line(tmp_path):
    """The issue's own command: `nsdrake drive panda_wipe --lcm memq://` where nobody
    publishes ends after the default wait (5 s) with one line and a non-zero exit, having
    sent nothing."""
    start = time.monotonic()
    result = subprocess.run(
        [sys.executable, "-m", "nsdrake", "drive", "panda_wipe", "--lcm", "memq://"],
        cwd=tmp_path,
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert result.returncode == 1
    assert without_notices(result.stderr) == (
        "nsdrake: error: panda_wipe: drive: before the first command: no lcmt_panda_status on PANDA_STATUS "
        "within 5 s; nothing was sent; stopped commanding after 0 command(s)\n"
    )
    assert time.monotonic() - start >= 5.0
    timing = json.loads((tmp_path / "runs" / "drive-panda_wipe" / "timing.json").read_text())
    assert timing["ticks"] == 0 and timing["commands"] == 0


def test_simulated_driver_writes_the_run_folder(tmp_path, capsys):
    out = tmp_path / "drive"
    code = main(
        [
            "drive",
            "panda_wipe",
            "--simulated-driver",
            "--duration",
            "0.05",
            "--realtime-rate",
            "0",
            "--out",
            str(out),
        ]
    )
    assert code == 1  # 0.05 s ends before contact: the contact figures fail honestly
    for name in ("traces.csv", "metrics.json", "scenario.yaml", "timing.json", "report.html"):
        assert (out / name).is_file(), name
    traces = Traces.read_csv(out / "traces.csv")
    assert len(traces) == 51 and "cmd7" in traces and "f_n_measured" in traces
    timing = json.loads((out / "timing.json").read_text())
    assert timing["ticks"] == timing["commands"] == 51
    assert timing["p50_us"] <= timing["p99_us"] <= timing["p999_us"] <= timing["max_us"]
    assert timing["gc_disabled"] is True
    printed = capsys.readouterr().out
    assert "nsdrake: timing: 51 ticks, status in to command out p50" in printed
    assert timing["statuses_skipped"] == 0 and timing["periods"] == 50  # lockstep: every status answered


@pytest.mark.parametrize(
    ("argv", "words"),
    [
        (["drive", "panda_wipe"], "one of the arguments --lcm --simulated-driver is required"),
        (["drive", "panda_wipe", "--lcm", "memq://", "--simulated-driver"], "not allowed with argument"),
        (
            ["drive", "fig3", "--simulated-driver"],
            "the Panda driver speaks 7 joints; the scenario's arm has 4",
        ),
        (
            ["drive", "panda_wipe", "--simulated-driver", "--realtime-rate", "-1"],
            "--realtime-rate must be >= 0",
        ),
        (
            ["drive", "panda_wipe", "--lcm", "bogus://x"],
            'cannot open the LCM bus bogus://x: LCM provider "bogus"',
        ),
        (["sim-driver", "panda_wipe"], "the following arguments are required: --lcm"),
    ],
)
def test_bad_input_is_one_line_and_exit_2(tmp_path, capsys, argv, words):
    assert exit_code([*argv, "--out", str(tmp_path / "x")] if argv[0] == "drive" else argv) == 2
    err = capsys.readouterr().err
    assert err.startswith("nsdrake: error: ") and err.count("\n") == 1 and words in err, err
    assert not (tmp_path / "x").exists()


def test_a_bad_driver_setting_is_refused(tmp_path, capsys):
    config = tmp_path / "c.yaml"
    config.write_text("driver: {force_source: wrist}\n")
    assert main(["drive", "panda_wipe", "--simulated-driver", "--config", str(config)]) == 2
    err = capsys.readouterr().err
    assert "driver.force_source: must be one of sensor, external_torque, got 'wrist'" in err


def test_the_standalone_simulated_driver_pairs_commands_with_statuses():
    """serve_simulated_driver on memq:// with a controller that answers each status at once
    with a zero command (the robot holds still: the driver adds g): it steps once per
    period, each step after the answer to its last status, for 0.1 s after the first."""
    scenario = load_scenario("panda_wipe")
    lcm = DrakeLcm("memq://")
    statuses = []

    def answer(data: bytes):
        status = lcmt_panda_status.decode(data)
        statuses.append(status)
        command = lcmt_panda_command()
        command.utime, command.control_mode_expected = status.utime, lcmt_panda_status.CONTROL_MODE_TORQUE
        command.num_joint_torque, command.joint_torque = 7, [0.0] * 7
        lcm.Publish("PANDA_COMMAND", command.encode())

    subscription = lcm.Subscribe("PANDA_STATUS", answer)  # noqa: F841
    served = serve_simulated_driver(scenario, lcm, duration=0.1)
    assert served.steps == 100 and served.commands >= 100
    assert np.max(np.abs(np.array(statuses[-1].joint_position) - np.array(statuses[0].joint_position))) < 1e-9
