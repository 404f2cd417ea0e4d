"""The drive over a real transport (issue 27, item 6): both sides as separate processes
talking UDP multicast inside a private network namespace (tests/driver/netns.py; skipped
with the reason where one cannot be made, required in CI)."""

from __future__ import annotations

import json
import math
import os
import random
import sys
from pathlib import Path

import pytest
from conftest import without_notices
from netns import URL, require_namespace, run_in_namespace
from udp_fault_runner import BOUND

from nsdrake.driver.faults import SLOW_STREAM
from nsdrake.experiment.scenario import load_scenario
from nsdrake.experiment.traces import Traces

HERE = Path(__file__).resolve().parent
ROOT = HERE.parents[1]
FAULTS = {  # injected by tests/driver/bad_driver.py; the words of the controller's one line
    "undecodable": "status refused: 24 bytes that are not an lcmt_panda_status",
    "nan": "status refused: joint_position[0] is nan",
    "position_limit": "status refused: panda_joint6 is at",
    "velocity_limit": "status refused: panda_joint1 moves at 3 rad/s, beyond the Panda's limit 2.175 rad/s",
    "two_publishers": "(a second publisher on the channel?)",
    "silence": "no lcmt_panda_status on PANDA_STATUS for ",
    "jump": "its robot_utime jumped 10800001.000 ms",
    "backward": "its robot_utime went back",
    "2khz": "the stream is faster than the controller's period of 1000 µs",
    "250hz": "the stream's period is not the controller's 1000 µs",
    "sensor_silence": "no lcmt_force_torque on PANDA_FORCE_TORQUE for ",
    "no_sensor": "before the first command: no lcmt_force_torque on PANDA_FORCE_TORQUE within 3 s although",
    "creep": "status refused: panda_joint7 moved ",
}


def python_in_namespace(args: str) -> str:
    return f"PYTHONPATH={ROOT}:{HERE} {sys.executable} {args}"


# Every fault over UDP runs with the whole suite (issue 46: the fast subset's costliest
# subprocess tests). Each fault's refusal, its one line and nothing sent after it, is tested
# in process for every fault on a fake bus (test_wire_faults.py, run_until_fault), and the
# UDP bus's delivery of every message by test_bus_queue.py.
FAST_FAULTS = ("nan", "silence")  # the first of the two parts: a refusal and a silence


@pytest.mark.slow
@pytest.mark.parametrize(
    "faults",
    [FAST_FAULTS, tuple(f for f in FAULTS if f not in FAST_FAULTS)],
    ids=["a refusal and a silence", "the other faults"],
)
def test_every_wire_fault_over_udp_is_one_line_and_nothing_after(tmp_path, faults):
    """Each fault of issue 27's items 3-4 injected by a driver process that misbehaves
    (tests/driver/bad_driver.py) over UDP, against the controller side in another
    process: it stops with its one line, the robot received no command after it (every
    command it got was counted before the fault, none answered the faulty status; it
    listens 0.4 s more, past the silence bound for a silence), and the run
    folder keeps what was computed (traces for the 100 commands sent before). Catches
    a fault that is not caught over a real socket (a refusal that only a fake bus
    triggers), a command sent after the fault, and a run folder that loses its traces.
    The two parameters together inject every fault."""
    require_namespace()
    script = python_in_namespace(f"{HERE / 'udp_fault_runner.py'} '{URL}' out {','.join(faults)}")
    result = run_in_namespace(script, cwd=tmp_path, timeout=600)
    reports = [json.loads(line) for line in result.stdout.splitlines() if line.startswith("{")]
    assert [r["fault"] for r in reports] == list(faults), result.stderr[-2000:]
    for r in reports:
        fault, failure = r["fault"], r["failure"]
        assert failure is not None and "\n" not in failure and FAULTS[fault] in failure, (fault, failure)
        assert f"stopped commanding after {r['commands']} command(s)" in failure
        if "silence" in fault:  # declared past the 1000 ms bound; how far past is the OS's (the
            # boundary itself is tested on a fake clock in test_wire_faults.py)
            waited = float(failure.split(" for ")[1].split(" ms")[0])
            assert 1000.0 <= waited < 1100.0, failure  # printed to 0.1 ms
        assert r["driver"]["commands"] == r["commands"], r  # nothing reached the robot after the fault
        # and none answered a faulty status, but those the rules take before they can tell: at
        # 2 kHz the first half-period status, at 250 Hz the first SLOW_STREAM - 1 slow ones,
        # with the sensor silent the statuses within the silence bound, with two publishers
        # the real driver's status that arrived before the second's
        taken = {"2khz": 1, "250hz": SLOW_STREAM - 1, "sensor_silence": int(BOUND), "two_publishers": 1}
        taken = taken.get(fault, 0)
        assert r["driver"]["after_fault"] <= taken, r
        if fault == "no_sensor":
            assert r["commands"] == 0 and "traces.csv" not in r["files"] and "timing.json" in r["files"]
            continue
        assert r["driver"]["injected"] and r["commands"] >= 100, r
        rows = len(Traces.read_csv(tmp_path / "out" / fault / "traces.csv"))
        assert rows == r["commands"], (fault, rows)
        metrics = json.loads((tmp_path / "out" / fault / "metrics.json").read_text())
        assert metrics["status"] == "failed" and metrics["failure"] == failure


def pair_script(duration: float, out: str, config: str | None = None) -> str:
    """nsdrake sim-driver and nsdrake drive, two processes on the namespace's bus, as the
    README's recipe runs them (the driver's filter off; commands expire after the
    scenario's driver.expire_sec, which both sides read: 50 ms as shipped). The driver
    serves 1 s longer than the drive: it counts from the first command it receives, the
    drive from the first status after it was ready."""
    config = f" --config {config}" if config else ""
    driver = python_in_namespace(
        f"-m nsdrake sim-driver panda_wipe --lcm '{URL}' --duration {duration + 1.0:g}{config} "
        "--low-pass-freq 1000"
    )
    drive = python_in_namespace(
        f"-m nsdrake drive panda_wipe --lcm '{URL}' --duration {duration:g}{config} --out {out}"
    )
    return (
        f"{driver} > driver.out 2> driver.err &\n{drive} > drive.out 2> drive.err\necho $? > drive.rc\nwait\n"
    )


@pytest.mark.slow  # its fast twins: test_drive_reproduces.py (the drive, in process), test_bus_queue.py (UDP)
def test_a_drive_over_udp_between_two_processes(tmp_path):
    """nsdrake drive against nsdrake sim-driver over UDP, free-running at 1 kHz for 1.75 s
    (through first contact, 1.44 s, and the force ramp): the whole drive ends without a
    fault, on the robot's clock (robot_utime; it ends at the first status at or after 1.75 s
    of it), one trace
    row per command, and the tool reached the table. Catches a drive that cannot run over
    UDP between processes at all (a bus that drops statuses, DrakeLcm's one-message queue
    answering stale ones), the clock read from utime. (Which status is answered, and the
    timing rules, are tested at their boundaries in test_wire_faults.py.) The silence bound
    is the most a scenario may set, 100 periods (driver.expire_sec 0.1 s, read by both
    sides): this test runs in the fast subset beside the suite's workers, where the
    simulated driver, a Python simulation, stalls for tens of ms."""
    require_namespace()
    (tmp_path / "c.yaml").write_text("driver: {expire_sec: 0.1}\n")
    result = run_in_namespace(pair_script(1.75, "out", "c.yaml"), cwd=tmp_path, timeout=600)
    err = without_notices((tmp_path / "drive.err").read_text())
    assert result.returncode == 0, result.stderr
    timing = json.loads((tmp_path / "out" / "timing.json").read_text())
    assert "failure" not in timing, (timing.get("failure"), err)
    # the robot's clock, to the period: the drive ends at the first status at or after 1.75 s
    # (a tick that skipped periods at the end may land a few periods past it)
    assert 1750 <= timing["periods"] <= 1750 + 200
    assert timing["clock"] == "robot_utime"
    traces = Traces.read_csv(tmp_path / "out" / "traces.csv")
    assert len(traces) == timing["commands"]
    assert traces["t"][-1] == pytest.approx(timing["periods"] * 1e-3, abs=1e-9)
    assert float(traces["f_n"].max()) > 2.0  # it reached the table: the run is a real one


ACCEPTANCE = "NSDRAKE_ACCEPTANCE"  # =1: run the 20 s acceptance (alone, on a quiet machine, as root)
# [%] the fresh share the acceptance asserts: issue 27's goal, 99 (bench/bench_drive.py keeps
# it); .ci/run sets a bound its machine holds in every run (the comment there gives the runs)
ACCEPTANCE_FRESH = "NSDRAKE_ACCEPTANCE_FRESH"


def acceptance_fresh() -> float:
    """The fresh share [%] the acceptance asserts (ACCEPTANCE_FRESH, default 99)."""
    text = os.environ.get(ACCEPTANCE_FRESH, "99")
    try:
        bound = float(text)
    except ValueError:
        bound = math.nan
    if not 0.0 < bound <= 100.0:
        pytest.fail(f"{ACCEPTANCE_FRESH}={text!r}: must be a share in percent, above 0 and at most 100")
    return bound


@pytest.mark.slow
def test_panda_wipe_free_running_over_udp_for_20_s(tmp_path):
    """Issues 27 and 35's acceptance: 20 s of panda_wipe over UDP between the two
    processes, free-running at 1 kHz real time at the shipped settings (the silence bound
    the driver's expiry, 50 ms): the drive exits 0 (no fault, every bound met), the
    controller's clock on the robot's (20 000 periods), and at least 99% of the simulated
    driver's periods between the first and the last command applied the answer to the
    previous status (NSDRAKE_ACCEPTANCE_FRESH: another share; .ci/run runs it at a bound
    its machine holds, from ten runs its comment gives). Both processes must keep real
    time, so it runs alone on a quiet machine (NSDRAKE_ACCEPTANCE=1), not beside the
    suite's workers: elsewhere it is skipped, saying how to run it.
    Catches a controller that answers late (a tick that costs a period, a wait that
    sleeps past the status), a silence bound that stops an ordinary PC's drive, and a
    drive that loses the robot's clock."""
    if os.environ.get(ACCEPTANCE) != "1":
        pytest.skip(f"the 20 s real-time acceptance runs alone, on a quiet machine: {ACCEPTANCE}=1")
    bound = acceptance_fresh()
    require_namespace()
    result = run_in_namespace(pair_script(20.0, "out"), cwd=tmp_path, timeout=900)
    assert result.returncode == 0, result.stderr
    err = (tmp_path / "drive.err").read_text()
    assert (tmp_path / "drive.rc").read_text().strip() == "0", err + (tmp_path / "drive.out").read_text()
    timing = json.loads((tmp_path / "out" / "timing.json").read_text())
    assert "failure" not in timing and 20000 <= timing["periods"] <= 20003
    assert timing["silence_bound_periods"] == 50.0
    metrics = json.loads((tmp_path / "out" / "metrics.json").read_text())
    assert metrics["status"] == "ok" and metrics["all_passed"] and len(metrics["metrics"]) > 5, metrics
    line = (tmp_path / "driver.out").read_text().splitlines()[-1]
    fresh = float(line.split("of them applied a fresh command (")[1].split("%")[0])
    print(f"acceptance: {line}; drive {json.dumps(timing)}")
    assert fresh >= bound, line


def test_a_command_beyond_the_limits_never_reaches_the_robot_over_udp(tmp_path):
    """Issue 43, item 1 over a real socket: `nsdrake drive` with a rated 2.9 kg payload (the
    tool 0.1 kg) whose centre of mass lies 6 m off the tool (its gravity beyond what joint 6
    may be sent) and a fault planted, the limiter bounding τ rather than what is sent
    (tests/driver/limiter_on_tau_drive.py: the drive's own limiter keeps every command
    inside), against a driver process that publishes a Panda at rest at the start pose and
    counts every command it receives: the drive stops at its first status with one line
    naming the joint, exit 1, and the robot received no command at all. Catches a gate that
    only a fake bus meets, and the command sent before it is checked."""
    require_namespace()
    (tmp_path / "hostile.yaml").write_text("arm: {payload: {mass: 2.9, com: [6.0, 0.0, 0.0]}}\n")
    q0 = load_scenario("panda_wipe").arm.initial_positions
    q = ",".join(repr(float(q0[f"panda_joint{k}"])) for k in range(1, 8))
    robot = python_in_namespace(f"{HERE / 'bad_driver.py'} --url '{URL}' --fault none --q {q} --seconds 300")
    drive = python_in_namespace(
        f"{HERE / 'limiter_on_tau_drive.py'} drive panda_wipe --lcm '{URL}' --config hostile.yaml --out out"
    )
    script = (
        f"{robot} > driver.out 2> driver.err &\npid=$!\n"
        f"{drive} > drive.out 2> drive.err\necho $? > drive.rc\nkill -TERM $pid; wait $pid\n"
    )
    result = run_in_namespace(script, cwd=tmp_path, timeout=600)
    err = without_notices((tmp_path / "drive.err").read_text())
    assert (tmp_path / "drive.rc").read_text().strip() == "1", (err, result.stderr)
    assert err.count("\n") == 1 and err.startswith(
        "nsdrake: error: panda_wipe: drive: before the first command: command refused, not sent: panda_joint"
    ), err
    assert err.endswith("stopped commanding after 0 command(s)\n"), err
    report = json.loads((tmp_path / "driver.out").read_text().splitlines()[-1])
    assert report["commands"] == 0, report
    assert json.loads((tmp_path / "out" / "timing.json").read_text())["commands"] == 0


def test_a_unicast_udpm_address_is_refused_in_one_line(tmp_path):
    """`--lcm udpm://10.1.2.3:7667` (a unicast address: LCM cannot join it as a multicast
    group) ends at once with one line and exit 2, before any folder (issue 24, item 4: it
    was accepted and failed 5 s later as "no status"). Inside the namespace: a udpm URL
    is never opened outside one."""
    require_namespace()
    drive = python_in_namespace("-m nsdrake drive panda_wipe --lcm 'udpm://10.1.2.3:7667?ttl=0' --out out")
    result = run_in_namespace(f"{drive}\necho $? > rc\n", cwd=tmp_path, timeout=300)
    assert (tmp_path / "rc").read_text().strip() == "2", result.stderr
    err = without_notices(result.stderr)
    assert err.count("\n") == 1 and "cannot open the LCM bus udpm://10.1.2.3:7667?ttl=0" in err, err
    assert not (tmp_path / "out").exists()


def test_ctrl_c_stops_the_simulated_driver_with_130(tmp_path):
    """`nsdrake sim-driver` serving on UDP, no controller: SIGINT ends it at the next
    period with one line and exit 130 (issue 24, item 3: it exited 1)."""
    require_namespace()
    driver = python_in_namespace(f"-m nsdrake sim-driver panda_wipe --lcm '{URL}'")
    script = (
        f"{driver} > out 2> err &\n"
        "pid=$!\n"
        "for i in $(seq 600); do grep -q serving out && break; sleep 0.2; done\n"
        "sleep 1; kill -INT $pid; wait $pid; echo $? > rc\n"
    )
    run_in_namespace(script, cwd=tmp_path, timeout=300)
    assert (tmp_path / "rc").read_text().strip() == "130"
    err = without_notices((tmp_path / "err").read_text())
    assert err == "nsdrake: simulated driver interrupted (Ctrl-C)\n", err


def interrupt_script(tries: int, seed: int) -> tuple[str, list[dict]]:
    """A bash script of ``tries`` drives (panda_wipe for 30 s, each into its own folder)
    each sent SIGINT at a random moment (seeded): even tries with no driver on the bus
    (the drive waits for its first status; SIGINT 0-1 s after it says it drives), odd
    tries beside a fresh nsdrake sim-driver (mid-run: 0.3-3 s after). Returns the script
    and the tries' plans."""
    rng = random.Random(seed)
    lines, plans = [], []
    wait = "for j in $(seq 1200); do grep -q {word} {file} && break; sleep 0.05; done"
    for i in range(tries):
        mid_run = i % 2 == 1
        delay = rng.uniform(0.3, 3.0) if mid_run else rng.uniform(0.0, 1.0)
        plans.append({"try": i, "mid_run": mid_run, "delay": round(delay, 3)})
        config = " --config c.yaml" if mid_run else ""
        drive = python_in_namespace(
            f"-m nsdrake drive panda_wipe --lcm '{URL}' --duration 30 --out out{i}{config}"
        )
        if mid_run:
            driver = python_in_namespace(  # the filter off, as the recipe runs it (30 Hz breaks the law)
                f"-m nsdrake sim-driver panda_wipe --lcm '{URL}'{config} --low-pass-freq 1000"
            )
            serving = wait.format(word="serving", file=f"s{i}.out")
            lines += [f"{driver} > s{i}.out 2> s{i}.err &", "spid=$!", serving]
        lines += [
            f"{drive} > d{i}.out 2> d{i}.err &",
            "pid=$!",
            wait.format(word="driving", file=f"d{i}.out"),
            f"sleep {delay:.3f}; kill -INT $pid; wait $pid; echo $? > d{i}.rc",
        ]
        if mid_run:
            lines += ["kill -INT $spid; wait $spid || true"]
    return "\n".join(lines) + "\n", plans


def check_interrupted(folder: Path, plan: dict) -> int | None:
    """One try of interrupt_script: exit 130, one line on stderr saying Ctrl-C, and the
    run folder kept, marked interrupted; returns the commands sent. None for a mid-run
    try whose drive had stopped on a fault of its own before the SIGINT came (a silence
    of the simulated driver, a Python simulation that a loaded machine stalls past the
    bound, or the arm it simulates driven past a velocity limit by stale commands meanwhile:
    seen in CI): no test of Ctrl-C."""
    i = plan["try"]
    err = without_notices((folder / f"d{i}.err").read_text())
    timing = json.loads((folder / f"out{i}" / "timing.json").read_text())
    if plan["mid_run"] and timing.get("status") == "failed" and "Ctrl-C" not in timing["failure"]:
        return None
    assert (folder / f"d{i}.rc").read_text().strip() == "130", (plan, err)
    assert err.count("\n") == 1 and "interrupted (Ctrl-C); stopped commanding after" in err, (plan, err)
    assert "marked interrupted" in err and "bus failed" not in err, (plan, err)
    assert timing["status"] == "interrupted", (plan, timing)
    commands = int(err.split("stopped commanding after ")[1].split(" ")[0])
    assert timing["commands"] == commands
    if commands:
        assert len(Traces.read_csv(folder / f"out{i}" / "traces.csv")) == commands
        assert json.loads((folder / f"out{i}" / "metrics.json").read_text())["status"] == "interrupted"
    return commands


# With the whole suite (issue 46): the fast twins of its rules are
# test_wire_faults.py::test_ctrl_c_during_a_wait_is_an_interrupt_not_a_bus_failure (the
# interrupted wait's OSError, in process) and test_drive_interrupt.py (Ctrl-C waiting for the
# first status on the lcm package's bus, and mid-drive, each in a process of its own). Ten
# tries only: the 2-try run that was the fast subset's, then ran beside this one in the
# whole suite, is the same script with one waiting and one mid-run try at random moments;
# the ten make five of each, and must have a mid-run try that commanded.
@pytest.mark.slow
@pytest.mark.parametrize("tries", [10], ids=["10 tries"])
def test_ctrl_c_at_random_moments_over_udp_is_an_interrupt(tmp_path, tries):
    """Issue 34, item 1: `nsdrake drive --lcm udpm://…` sent SIGINT at random moments
    (interrupt_script: waiting for the first status, and mid-run beside nsdrake
    sim-driver) ends every time with one line, exit 130, the folder kept and marked
    interrupted. Catches the interrupted wait for a status (LCM's select() returning
    EINTR, raised by the lcm package as an OSError) taken for a bus failure ("the LCM bus
    failed", exit 1: every waiting try and most mid-run ones before the fix), and a
    SIGINT between the drive's first line and its loop that undoes the folder. The mid-run
    tries (silence bound 0.1 s on both sides: the most a scenario may set) must have
    commanded; one whose drive the loaded machine had stopped on a silence first is no
    test of Ctrl-C and is counted aside, and of five, at least one must be a test. The
    seed is printed for a failure to be replayed."""
    require_namespace()
    seed = random.SystemRandom().randrange(1 << 30)
    print(f"seed {seed}")
    (tmp_path / "c.yaml").write_text("driver: {expire_sec: 0.1}\n")
    script, plans = interrupt_script(tries, seed)
    result = run_in_namespace(script, cwd=tmp_path, timeout=120 * tries)
    assert result.returncode == 0, result.stderr
    tested = 0
    for plan in plans:
        commands = check_interrupted(tmp_path, plan)
        if plan["mid_run"] and commands is not None:
            assert commands > 0, plan
            tested += 1
    print(f"{tested} of {tries // 2} mid-run tries interrupted mid-run (the others: a silence first)")
    assert tested >= (1 if tries >= 10 else 0)
