"""Benchmark: the drive's tick, status arrival to command publish, over memq:// and over UDP.

    python bench/bench_drive.py [--duration 20] [--out DIR] [--transport memq|udp|both]
                                [--config FILE|default ...] [--realtime] [--loop-runs 3]
                                [--filter [--filter-duration S]] [--soak SECONDS]
                                [--settings FILE|default] [--profile]

``memq``: panda_wipe's first ``--duration`` seconds through the controller side and the
simulated driver in one process (lockstep, the driver paced at real time: one status
per millisecond).

``udp``: ``nsdrake sim-driver`` and ``nsdrake drive`` as two processes over UDP multicast
inside a private network namespace (``unshare -n``, root; tests/driver/netns.py says
why), free-running at 1 kHz as the README's robot recipe runs them (the driver's filter
off, commands expiring after the scenario's ``driver.expire_sec``, 50 ms as shipped,
which is also the controller's silence bound); also the driver's own count of the
periods that applied a fresh command, a stale one, or fell back to damping, and how many
it started late itself (the simulated driver is a Python simulation of the plant: on a
loaded machine it cannot keep 1 kHz either). ``--config`` is passed to both; repeated,
one UDP run per file (``default``: the scenario as shipped), each in its own folder
under ``--out``. Each run reports the longest silence the loop's silence rule measured
(``longest_silence_us``: how near the stream came to the bound) and whether panda_wipe
met its bounds.

``--realtime``: each UDP run again with both sides in the real-time mode
(:mod:`nsdrake.driver.realtime`, ``REALTIME``): the simulated driver at SCHED_FIFO 80 on
core 0, the controller at SCHED_FIFO 80 on core 1, memory locked, the collector off; a row
of its own, labelled with the settings each side read back.

Then ``--loop-runs`` runs of the loop alone (``--profile``'s measurement, unprofiled),
their medians. Writes ``table.md`` under ``--out``, one row per run (docs/results/drive/
keeps the one the docs show). Each UDP run prints every bounded metric of panda_wipe with
its bound and verdict (its metrics.json); after the table, one line per UDP run with issue
44's figures: tick / step at p50 and p99.9 (the plain step measured in the same bench
run, with ``--loop-runs``), the driver's fresh share and its own CPU per period, and how
the run ended (its bounds, or the fault that stopped it).

``--filter``: panda_wipe (``--filter-duration``, default the whole scenario) over UDP with
the simulated driver's torque low-pass at 30 Hz (drake-franka-driver's default
``--low_pass_freq``), 100 Hz (libfranka's) and off: force and pose errors, the closest
the elbow came to the post, saturated joints, whether every bound was met; writes
``filter/table.md``. ``--soak SECONDS``: one UDP run of panda_wipe that long, the circle
extended by as many laps as fit (``soak.yaml`` under ``--out``): stops, the driver's
fresh share, the drive's glitch counts (``gaps`` in timing.json: statuses answered 2,
3–10, 11–50 periods after the previous one), the controller's clock against the robot's
at the end (the simulated driver reports the robot time of the statuses its first and
last commands answered), each tick's CPU p50/p99.9; writes ``soak/table.md``. Both use
``--settings`` (a ``--config`` for both sides; default the shipped settings).

Each tick's CPU time is the loop thread's (``time.thread_time``), from the status's
arrival to the command's publish: what the controller itself costs, apart from the time
the machine preempted it. The machine's 1-minute load average is recorded before and
after each run (read the wall-clock figures with it). Writes the drives' timing.json
files under ``--out`` (default ``bench/out/drive``) and ends with one JSON line:
``cpu_p50_us`` and ``cpu_p999_us`` of the UDP run (of memq without a namespace), each
transport's figures, the targets (issue 27: 80 and 200 µs) and the load.

``--profile``: the loop alone, replaying on an in-process bus (``lcm`` memq://) the
statuses and sensor messages the simulated driver published in a 6 s lockstep panda_wipe
(approach, contact, the start of the circle), unpaced: the ticks' CPU time p50 and
p99.9 (the controller's own cost, without the driver's simulation in the same thread or
on the same core), then where it goes under cProfile (the shares of the controller's
step, the reference, the status checks, the record and the bus; a ratio: the profiler
inflates Python more than C++).
"""

from __future__ import annotations

import argparse
import cProfile
import json
import os
import pstats
import re
import shutil
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import yaml

from nsdrake.driver.run import prepare, run_simulated, write_drive_folder
from nsdrake.driver.timing import collector_paused, timing_line
from nsdrake.experiment.driver_config import silence_bound_periods
from nsdrake.experiment.scenario import load_scenario

ROOT = Path(__file__).resolve().parents[1]
OUT = ROOT / "bench" / "out" / "drive"
URL = "udpm://239.255.76.67:7667?ttl=0"  # used only inside the private namespace below
TARGETS = {"cpu_p50_us": 80.0, "cpu_p999_us": 200.0}
KEYS = ("ticks", "cpu_p50_us", "cpu_p99_us", "cpu_p999_us", "cpu_max_us", "p50_us", "p99_us", "p999_us",
        "max_us", "over_period", "statuses_skipped", "longest_silence_us", "periods", "failure", "commands",
        "period_us", "gaps", "longest_gap_periods")  # fmt: skip


def memq(duration: float, out: Path) -> dict:
    load = os.getloadavg()[0]
    run = run_simulated(load_scenario("panda_wipe", duration=duration), realtime_rate=1.0)
    timing = dict(run.timing) | {"load_average_1min": [load, os.getloadavg()[0]], "failure": run.failure}
    folder = out / "memq"
    shutil.rmtree(folder, ignore_errors=True)
    folder.mkdir(parents=True)
    timing["bounds_met"] = write_drive_folder(run, folder).passed  # the run's metrics against its bounds
    print(f"memq: {timing_line(timing)}")
    return {key: timing.get(key) for key in (*KEYS, "load_average_1min", "bounds_met")}


NAMESPACE = (
    '[ "$(ip -o link show | wc -l)" = 1 ] || exit 97\n'
    "ip link set lo up && ip link set lo multicast on && ip route add 224.0.0.0/4 dev lo\n"
)


DRIVER_LINE = re.compile(
    r"(\d+) periods from the first command to the last, (\d+) of them applied a fresh command .*; "
    r"in all (\d+) periods after the first command, (\d+) commands received; (\d+) applied a fresh "
    r"command, (\d+) a stale one, (\d+) fell back to damping; the driver itself started (\d+)"
)
ANSWERED = re.compile(r"the commands answered the statuses from robot time (\d+) µs to (\d+) µs")
DRIVER_CPU = re.compile(r"its own CPU (\d+) µs per period")
DRIVER_REALTIME = re.compile(r"real-time: SCHED_FIFO (\d+) on cores \[([\d, ]+)\]")
# the real-time mode of the UDP runs with --realtime: the driver on one core, the controller on
# the other, both at SCHED_FIFO 80 with memory locked (nsdrake/driver/realtime.py)
REALTIME = {"driver": "--realtime --realtime-core 0", "drive": "--realtime --realtime-core 1"}


def udp(
    duration: float, out: Path, config: Path | None, *, name: str = "", driver: str = "", drive: str = ""
):
    """``nsdrake sim-driver`` and ``nsdrake drive`` over UDP in a private namespace (module
    docstring), ``config`` given to both, ``driver`` and ``drive`` options added to each
    (the filter: ``--low-pass-freq 1000``, off, unless given; real time); the run's folder
    ``out/udp-NAME``."""
    if shutil.which("unshare") is None or os.geteuid() != 0:
        return {"failure": "no private network namespace here (unshare -n needs root)"}
    folder = out / f"udp-{name or (config.stem if config else 'default')}"
    shutil.rmtree(folder, ignore_errors=True)
    python = f"PYTHONPATH={ROOT} {sys.executable} -m nsdrake"
    options = f" --config {config.resolve()}" if config else ""
    low_pass = "" if "--low-pass-freq" in driver else " --low-pass-freq 1000"
    script = (
        NAMESPACE + f"{python} sim-driver panda_wipe --lcm '{URL}' --duration {duration + 1:g}{options} "
        f"{driver}{low_pass} > {folder.name}-driver.out 2>&1 &\n"
        + f"{python} drive panda_wipe --lcm '{URL}' --duration {duration:g}{options} {drive} --out {folder}"
        + f" > {folder.name}-drive.out 2>&1\nwait\n"
    )
    load = os.getloadavg()[0]
    subprocess.run(
        ["unshare", "-n", "--fork", "--kill-child", "bash", "-c", script],
        cwd=out,
        timeout=duration * 10 + 600,
    )
    if not (folder / "timing.json").exists():
        lines = (out / f"{folder.name}-drive.out").read_text().strip().splitlines()
        return {"failure": lines[-1] if lines else "the drive wrote nothing"}
    timing = json.loads((folder / "timing.json").read_text())
    timing["load_average_1min"] = [load, os.getloadavg()[0]]
    metrics = json.loads((folder / "metrics.json").read_text()) if (folder / "metrics.json").exists() else {}
    timing["failure"] = metrics.get("failure", timing.get("failure"))
    timing["bounds_met"] = metrics.get("all_passed")
    driver_line = (out / f"{folder.name}-driver.out").read_text()
    print(f"{folder.name}: {timing_line(timing)}")
    print(f"{folder.name}: {driver_line.strip().splitlines()[-1]}")
    result = {key: timing.get(key) for key in (*KEYS, "load_average_1min", "bounds_met")}
    result["silence_bound_periods"] = silence_bound(config)
    result["metrics"] = {name: float(m["value"]) for name, m in (metrics.get("metrics") or {}).items()}
    result["bounds"] = bounds(metrics)
    print(f"{folder.name}: every bound: " + ("; ".join(result["bounds"]) or "none (the run stopped)"))
    result["realtime"] = timing.get("realtime")
    result["driver"] = driver_figures(driver_line)
    return result


def bounds(metrics: dict) -> list[str]:
    """Each of the run's metrics that has a bound: its value, the bound, met or not (metrics.json)."""
    lines = []
    for name, m in (metrics.get("metrics") or {}).items():
        if m.get("passed") is None:
            continue
        lines.append(
            f"{name} {m['value']:.4g} {m['unit']} ({m['bound']}): {'met' if m['passed'] else 'NOT met'}"
        )
    return lines


def driver_figures(driver_line: str) -> dict:
    """The simulated driver's own counts, from its last line (nsdrake.driver.serve.ServeResult.line)."""
    numbers = DRIVER_LINE.search(driver_line)
    if not numbers:
        return {}
    commanded, commanded_fresh, periods, commands, fresh, stale, expired, behind = (
        int(x) for x in numbers.groups()
    )
    answered = ANSWERED.search(driver_line)
    realtime = DRIVER_REALTIME.search(driver_line)
    cpu = DRIVER_CPU.search(driver_line)
    return {
        "cpu_per_period_us": int(cpu.group(1)) if cpu else None,
        "periods": periods, "commands": commands, "fresh": fresh, "stale": stale, "expired": expired,
        "started_late": behind, "commanded_periods": commanded,
        "fresh_fraction": commanded_fresh / commanded if commanded else None,
        "answered_robot_us": [int(x) for x in answered.groups()] if answered else None,
        "realtime": {"priority": int(realtime.group(1)), "cores": realtime.group(2)} if realtime else None,
    }  # fmt: skip


def silence_bound(config: Path | None) -> float:
    """The drive's silence bound [periods] with ``config`` overlaid on panda_wipe."""
    scenario = load_scenario("panda_wipe", config=config)
    return silence_bound_periods(scenario.driver, scenario.control_period)


def cell(value, unit: str = " µs", digits: int = 0) -> str:
    return "–" if value is None else f"{value:.{digits}f}{unit}"


def table(results: dict) -> str:
    """The measured table (docs/results/drive/table.md): one row per run."""
    header = (
        "| panda_wipe at 1 kHz | load (1 min) | ran | CPU p50 | CPU p99.9 | tick / step p50 "
        "| tick / step p99.9 | wall p50 | wall p99.9 | ticks over 1 ms | statuses skipped "
        "| late statuses: 2 / 3–10 / 11–50 periods (longest) | longest silence | driver: fresh commands "
        "| driver: CPU per period | bounds met |\n"
        "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|\n"
    )
    rows = []
    loop = results.get("loop_alone")
    if loop:
        rows.append(
            f"| loop alone: a recorded 6 s, in-process bus, unpaced (median of {loop['runs']}) "
            f"| {loop['load_average_1min']:.2f} | {loop['ticks']} ticks | {cell(loop['cpu_p50_us'])} "
            f"| {cell(loop['cpu_p999_us'])} | {ratio_cells(loop)} | – | – | – | – | – | – | – | – | – |"
        )
        rows.append(
            f"| plain ControllerStep.step: the same calls, back to back (median of {loop['runs']}) "
            f"| {loop['load_average_1min']:.2f} | {loop['ticks']} calls | {cell(loop['step_cpu_p50_us'])} "
            f"| {cell(loop['step_cpu_p999_us'])} | 1.00 | 1.00 | – | – | – | – | – | – | – | – | – |"
        )
    runs = [("memq://, lockstep with the simulated driver", results.get("memq"))]
    runs += [(udp_label(r), r) for r in results.get("udp_runs", [])]
    for label, r in runs:
        if not r:
            continue
        if r.get("ticks") is None:
            rows.append(f"| {label} | – | not run: {r.get('failure')} |" + " – |" * 13)
            continue
        load = r["load_average_1min"]
        ran = f"{results['duration_s']:g} s" if not r.get("failure") else f"stopped: {r['failure']}"
        driver = r.get("driver") or {}
        fresh = driver.get("fresh_fraction")
        lockstep = r is results.get("memq")  # the robot waits for the controller: no silence
        silence = "–" if lockstep else cell(r["longest_silence_us"] / 1e3, " ms", 2)
        rows.append(
            f"| {label} | {load[0]:.2f}–{load[1]:.2f} | {ran} | {cell(r['cpu_p50_us'])} "
            f"| {cell(r['cpu_p999_us'])} | {ratio_cells(r)} | {cell(r['p50_us'])} | {cell(r['p999_us'])} "
            f"| {r['over_period']} | {r['statuses_skipped']} | {'–' if lockstep else glitches(r)} "
            f"| {silence} | {percent(fresh)} | {cell(driver.get('cpu_per_period_us'))} "
            f"| {'– (stopped)' if r.get('failure') else ('yes' if r.get('bounds_met') else 'no')} |"
        )
    title = (
        "# drive\n\n"
        "panda_wipe driven by `nsdrake drive` against the simulated driver: CPU and wall figures are the "
        "tick's, from a status's arrival to the command's publish; the longest silence is the longest "
        "time the loop waited for a status from the last one's arrival (the silence rule's measure); "
        "late statuses are those answered two periods or more after the previous one, within the "
        "silence bound (the drive's glitch counts); "
        "fresh commands are the driver's share of periods that applied a command answering its "
        "previous status, and its CPU per period the simulated driver's own (its plant's step and its "
        "bus), beside the controller. Tick / step: each row's CPU p50 and p99.9 over the plain "
        "ControllerStep.step's, measured in the same run on the arguments the loop gave it in the "
        "replay (issue 44's targets: 1.5 and 2). This machine's figures, with its load.\n\n"
    )
    return title + header + "\n".join(rows) + "\n"


def summary(r: dict) -> str:
    """One UDP run's issue 44 figures in a line: tick / step (p50, p99.9, the plain step measured
    in the same bench run), the driver's fresh share and its own CPU per period, the bounds."""
    driver, load = r.get("driver") or {}, r.get("load_average_1min")
    ratio = (
        f"tick / step {r['tick_over_step_p50']:.2f} (p50), {r['tick_over_step_p999']:.2f} (p99.9)"
        if r.get("tick_over_step_p50") is not None
        else "tick / step not measured (--loop-runs 0)"
    )
    ended = f"bounds {'met' if r.get('bounds_met') else 'NOT met'}"
    if r.get("failure"):  # no metrics were computed: "bounds met" would be vacuous
        ended = f"stopped: {r['failure']}"
    return (
        f"{udp_label(r)}: {ratio}; driver: fresh {percent(driver.get('fresh_fraction'))}, "
        f"its own CPU {cell(driver.get('cpu_per_period_us'))} per period; "
        f"{ended} (load {cell(load[0] if load else None, '', 2)})"
    )


def ratio_cells(r: dict) -> str:
    """The tick / step cells (p50, p99.9)."""
    if r.get("tick_over_step_p50") is None:
        return "– | –"
    return f"{r['tick_over_step_p50']:.2f} | {r['tick_over_step_p999']:.2f}"


def udp_label(r: dict) -> str:
    """A UDP row's label: its silence bound, and each side's real-time mode as it read it back."""
    label = f"UDP, two processes, silence bound {r.get('silence_bound_periods', 0):g} periods"
    controller = r.get("realtime") or {}
    driver = (r.get("driver") or {}).get("realtime")
    sides = []
    if driver:
        sides.append(f"driver SCHED_FIFO {driver['priority']} on core {driver['cores']}")
    if controller.get("policy") == "SCHED_FIFO":
        locked = controller["memory_locked_kb"] > 0
        sides.append(
            f"controller SCHED_FIFO {controller['priority']} on core "
            f"{','.join(str(c) for c in controller['cores'])}{', memory locked' if locked else ''}"
        )
    return label + (", real-time: " + "; ".join(sides) if sides else "")


# the driver's torque low-pass for --filter: drake-franka-driver's default --low_pass_freq,
# libfranka's own default cutoff, and off (libfranka's kMaxCutoffFrequency, 1000 Hz)
FILTERS = (
    (30.0, "30 Hz (drake-franka-driver's default --low_pass_freq)"),
    (100.0, "100 Hz (libfranka's default)"),
    (1000.0, "off (1000 Hz; the README's robot recipe)"),
)
# (column, metric, unit, scale, digits) of panda_wipe's metrics.json for the filter table
FILTER_METRICS = (
    ("force error RMS", "force_error_rms", " N", 1.0, 3),
    ("position error RMS", "position_error_rms", " mm", 1e3, 2),
    ("orientation error max", "orientation_error_max", "°", 1.0, 2),
    ("elbow to the post, closest", "d_post_min", " mm", 1e3, 1),
    ("saturated joints, most", "saturated_joints_max_in_window", "", 1.0, 0),
)


def filter_runs(duration: float, out: Path, config: Path | None, realtime: bool) -> list[dict]:
    """panda_wipe over UDP at each of FILTERS (the simulated driver's --low-pass-freq, its
    rate limiter on as libfranka's), ``config`` given to both sides; both real-time with
    ``realtime`` (the law's figures then owe nothing to this machine's other load)."""
    runs = []
    for hz, label in FILTERS:
        options = REALTIME if realtime else {"driver": "", "drive": ""}
        driver = f"{options['driver']} --low-pass-freq {hz:g}"
        run = udp(duration, out, config, name=f"filter-{hz:g}", driver=driver, drive=options["drive"])
        runs.append(run | {"filter": label, "duration_s": duration})
    return runs


def filter_table(runs: list[dict], config: Path | None, realtime: bool) -> str:
    """docs/results/drive/filter/table.md: the law against the driver's torque filter."""
    header = (
        "| driver's torque low-pass | load (1 min) | ran | "
        + " | ".join(column for column, *_ in FILTER_METRICS)
        + " | driver: fresh commands | bounds met |\n|"
        + "---|" * (len(FILTER_METRICS) + 5)
        + "\n"
    )
    rows = []
    for r in runs:
        if r.get("ticks") is None:
            rows.append(
                f"| {r['filter']} | – | not run: {r.get('failure')} |" + " – |" * (len(FILTER_METRICS) + 2)
            )
            continue
        load, metrics = r["load_average_1min"], r.get("metrics") or {}
        ran = f"{r['duration_s']:g} s" if not r.get("failure") else f"stopped: {r['failure']}"
        figures = " | ".join(
            cell(None if metrics.get(name) is None else metrics[name] * scale, unit, digits)
            for _, name, unit, scale, digits in FILTER_METRICS
        )
        fresh = (r.get("driver") or {}).get("fresh_fraction")
        rows.append(
            f"| {r['filter']} | {load[0]:.2f}–{load[1]:.2f} | {ran} | {figures} "
            f"| {'–' if fresh is None else f'{100 * fresh:.2f}%'} | {bounds_cell(r)} |"
        )
    title = (
        "# drive: the driver's filter\n\n"
        "panda_wipe driven by `nsdrake drive` against `nsdrake sim-driver` over UDP, free-running at "
        "1 kHz, the simulated driver low-passing the torque as libfranka does (a first-order filter at "
        "the cutoff, then the 1000 N m/s rate limit) at drake-franka-driver's default cutoff, "
        "libfranka's, and off"
        + (f"; both sides with `--config {config.as_posix()}`" if config else ", at the shipped settings")
        + (
            "; both sides real-time (`--realtime`, the driver on core 0, the controller on core 1)"
            if realtime
            else ""
        )
        + ". Force and pose errors are panda_wipe's metrics (from 0.5 s after first contact); "
        "bounds met: every one of its bounds.\n\n"
    )
    return title + header + "\n".join(rows) + "\n"


def glitches(r: dict) -> str:
    """The drive's late statuses (timing.json's ``gaps``): how many 2, 3–10, 11–50 periods
    after the previous one, and the longest."""
    gaps = r.get("gaps")
    if gaps is None:
        return "– (this drive counts none)"
    counts = f"{gaps.get('2', 0)} / {gaps.get('3-10', 0)} / {gaps.get('11-50', 0)}"
    counts += f", {gaps['over 50']} over 50" if gaps.get("over 50") else ""
    return counts + f" ({r.get('longest_gap_periods')} periods)" if r.get("longest_gap_periods") else counts


def percent(fraction: float | None) -> str:
    return "–" if fraction is None else f"{100 * fraction:.2f}%"


def bounds_cell(r: dict) -> str:
    return "– (stopped)" if r.get("failure") else ("yes" if r.get("bounds_met") else "no")


def soak_config(seconds: float, config: Path | None, out: Path) -> Path:
    """``config`` with panda_wipe's circle extended to ``seconds``: as many more laps as fit,
    the path ending as far before the end as the shipped 28 s run's (a run shorter than the
    shipped one keeps its laps and ends before them)."""
    scenario = load_scenario("panda_wipe", config=config)
    r = scenario.reference
    lap = 2.0 * np.pi * r.radius / r.tangent_speed  # [s]
    laps = r.laps + max(0.0, np.floor((seconds - scenario.duration) / lap))  # a shorter run: the shipped laps
    data = yaml.safe_load(config.read_text()) if config else {}
    data = data or {}
    data.setdefault("reference", {})["laps"] = float(laps)
    path = out / "soak.yaml"
    path.write_text(yaml.safe_dump(data, sort_keys=False))
    return path


def soak(seconds: float, out: Path, config: Path | None) -> dict:
    """panda_wipe for ``seconds`` over UDP, free-running, ``config`` (more laps): the soak."""
    settings = soak_config(seconds, config, out)
    run = udp(seconds, out, settings, name="soak")
    laps = load_scenario("panda_wipe", config=settings).reference.laps
    traces = out / "udp-soak" / "traces.csv"
    if traces.exists():  # about 1 GB for 10 minutes; its metrics are in metrics.json
        traces.unlink()
    return run | {"duration_s": seconds, "laps": laps, "config": config}


def soak_table(r: dict) -> str:
    """docs/results/drive/soak/table.md: the soak's one row."""
    header = (
        "| panda_wipe, free-running over UDP | load (1 min) | stops | driver: fresh commands "
        "| late statuses: 2 / 3–10 / 11–50 periods (longest) | statuses skipped | longest silence "
        "| controller's clock − robot's, at the end | CPU p50 | CPU p99.9 | wall p99.9 | bounds met |\n"
        "|---|---|---|---|---|---|---|---|---|---|---|---|\n"
    )
    label = f"{r['duration_s']:g} s, {r['laps']:g} lap{'' if r['laps'] == 1 else 's'}"
    if r.get("ticks") is None:
        return (
            "# drive: soak\n\n"
            + header
            + f"| {label} | – | not run: {r.get('failure')} |"
            + " – |" * 9
            + "\n"
        )
    load, driver = r["load_average_1min"], r.get("driver") or {}
    fresh = driver.get("fresh_fraction")
    stops = "0" if not r.get("failure") else f"1: {r['failure']}"
    answered = driver.get("answered_robot_us")
    drift = (
        "–"
        if not answered or r.get("periods") is None or r.get("failure")
        else f"{r['periods'] * r['period_us'] - (answered[1] - answered[0]):+.0f} µs"
    )
    row = (
        f"| {label} | {load[0]:.2f}–{load[1]:.2f} | {stops} | {percent(fresh)} "
        f"| {glitches(r)} | {r['statuses_skipped']} | {cell(r['longest_silence_us'] / 1e3, ' ms', 2)} "
        f"| {drift} "
        f"| {cell(r['cpu_p50_us'])} | {cell(r['cpu_p999_us'])} | {cell(r['p999_us'])} | {bounds_cell(r)} |"
    )
    title = (
        "# drive: soak\n\n"
        "panda_wipe's circle driven lap after lap by `nsdrake drive` against `nsdrake sim-driver` over "
        "UDP in a private namespace, free-running at 1 kHz"
        + (
            f", both sides with `--config {r['config'].as_posix()}`"
            if r.get("config")
            else ", at the shipped settings"
        )
        + ": stops (the drive ended before its time), the simulated driver's share of periods that applied "
        "the answer to its previous status, the statuses answered two periods or more after the previous "
        "one (the drive's glitch counts), the controller's clock at its last command against the robot's "
        "clock of the status it answered (both from the first command), each tick's CPU time. This "
        "machine's figures, with its load.\n\n"
    )
    return title + header + row + "\n"


def recorded_statuses(duration: float) -> list[tuple[bytes, bytes]]:
    """The (status, force-torque) messages the simulated driver published in a lockstep
    panda_wipe drive of ``duration`` [s]: a real sequence, through approach and contact."""
    drive = prepare(load_scenario("panda_wipe", duration=duration), realtime_rate=0.0)
    pairs: list[list] = []

    def on_status(data):
        pairs.append([data, None])

    def on_force_torque(data):
        pairs[-1][1] = data

    drive.loop.bus.subscribe("PANDA_STATUS", on_status)
    drive.loop.bus.subscribe("PANDA_FORCE_TORQUE", on_force_torque)
    drive.run()
    return [tuple(pair) for pair in pairs]


class Replay:
    """The loop alone, replaying a recorded panda_wipe sequence (:func:`recorded_statuses`,
    ``duration`` [s]) on an in-process bus (``lcm`` memq://), unpaced; and the plain
    ``ControllerStep.step`` alone on the arguments the loop gave it in that replay."""

    def __init__(self, duration: float = 6.0):
        from nsdrake.driver.bus import LcmBus
        from nsdrake.driver.controller_side import build_controller_side

        self.pairs = recorded_statuses(duration)
        self.side = build_controller_side(load_scenario("panda_wipe", duration=duration))
        self.bus = LcmBus("memq://")
        self.calls = []
        self.ticks(record=True)

    def ticks(self, profiler=None, record: bool = False) -> np.ndarray:
        """Each tick's CPU time [µs] (the loop's own measure: a status's arrival to the
        command's publish); ``record``: keep each ControllerStep.step call's arguments."""
        from nsdrake.driver.loop import ControllerLoop

        side, bus = self.side, self.bus
        side.reset()
        loop = ControllerLoop(side, bus)
        if record:
            step = side.step.step

            def recorded(*args):
                self.calls.append(tuple(np.array(a) if isinstance(a, np.ndarray) else a for a in args))
                return step(*args)

            side.step.step = recorded  # an instance attribute: the loop calls it
        try:
            with collector_paused():
                loop.ready()
                for k, (status, sensor) in enumerate(self.pairs):
                    bus.publish("PANDA_STATUS", status)
                    bus.publish("PANDA_FORCE_TORQUE", sensor)
                    if k == 0:
                        loop.start()
                        if profiler is not None:
                            profiler.enable()
                    else:
                        loop.tick()
                if profiler is not None:
                    profiler.disable()
        finally:
            side.step.__dict__.pop("step", None)
        return loop.times.cpu_seconds * 1e6

    def steps(self) -> np.ndarray:
        """Each plain ControllerStep.step call's CPU time [µs], back to back, on the replay's
        arguments (the same states, the same contact and reference)."""
        step = self.side.step
        step.reset()
        cpu = np.empty(len(self.calls))
        with collector_paused():
            for k, args in enumerate(self.calls):
                start = time.thread_time()
                step.step(*args)
                cpu[k] = time.thread_time() - start
        return cpu * 1e6


def figures(cpu: np.ndarray) -> dict:
    return {"cpu_p50_us": float(np.percentile(cpu, 50)), "cpu_p999_us": float(np.percentile(cpu, 99.9))}


def loop_alone(rounds: int) -> dict:
    """``rounds`` alternating rounds of the loop alone and of the plain step (:class:`Replay`):
    the medians of each one's p50 and p99.9, and the ratios tick / step of those medians."""
    replay = Replay()
    ticks, steps, loads = [], [], []
    for _ in range(rounds):
        loads.append(os.getloadavg()[0])
        ticks.append(figures(replay.ticks()))
        steps.append(figures(replay.steps()))
    result = {"runs": rounds, "ticks": len(replay.pairs), "load_average_1min": float(np.median(loads))}
    for name, runs in (("", ticks), ("step_", steps)):
        for key in ("cpu_p50_us", "cpu_p999_us"):
            result[name + key] = float(np.median([r[key] for r in runs]))
    return result | ratios(result, result)


def ratios(tick: dict, step: dict) -> dict:
    """The tick's CPU p50 and p99.9 over the plain step's (issue 44's targets: 1.5 and 2)."""
    if not step or step.get("step_cpu_p50_us") is None or tick.get("cpu_p50_us") is None:
        return {}
    return {
        "tick_over_step_p50": tick["cpu_p50_us"] / step["step_cpu_p50_us"],
        "tick_over_step_p999": tick["cpu_p999_us"] / step["step_cpu_p999_us"],
    }


def profile(duration: float = 6.0) -> dict:
    """The loop alone (:class:`Replay`): its ticks' CPU time unprofiled, the plain step's,
    then where the tick goes under cProfile."""
    replay = Replay(duration)
    cpu = replay.ticks()  # unprofiled: the tick's own CPU time
    step = replay.steps()
    profiler = cProfile.Profile(time.thread_time)
    replay.ticks(profiler)
    stats = pstats.Stats(profiler)
    total = sum(v[3] for k, v in stats.stats.items() if k[2] == "tick" and "loop.py" in k[0])

    def cumulative(file: str, function: str) -> float:
        return sum(v[3] for k, v in stats.stats.items() if k[2].endswith(function) and file in k[0])

    shares = {
        "ControllerStep.step": cumulative("control/step.py", "step"),
        "reference": cumulative("experiment/reference.py", "tick"),
        "status decode and checks (compiled)": cumulative("driver/loop.py", "tick")
        - cumulative("driver/loop.py", "_answer")
        - cumulative("driver/loop.py", "_wait_for_a_status"),
        "record": cumulative("driver/controller_side.py", "record"),
        "bus (handle, publish)": cumulative("driver/bus.py", "handle")
        + cumulative("driver/bus.py", "publish"),
    }
    result = {"ticks": int(cpu.size), "load_average_1min": os.getloadavg()[0]} | figures(cpu)
    result |= {"step_" + key: value for key, value in figures(step).items()}
    return (
        result
        | ratios(result, result)
        | {"share_of_tick_under_cprofile": {name: seconds / total for name, seconds in shares.items()}}
    )


def arguments():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--duration", type=float, default=20.0, help="drive length [s]")
    parser.add_argument("--out", type=Path, default=OUT)
    parser.add_argument("--transport", choices=("memq", "udp", "both"), default="both")
    parser.add_argument(
        "--config",
        type=config_path,
        action="append",
        help="a --config for both sides of a UDP run; repeat for several runs ('default': none)",
    )
    parser.add_argument(
        "--realtime",
        action="store_true",
        help="each UDP run again with both sides real-time (REALTIME), and the filter runs real-time",
    )
    parser.add_argument(
        "--filter", action="store_true", help="the filter table: panda_wipe at each of FILTERS"
    )
    parser.add_argument(
        "--filter-duration",
        type=float,
        default=None,
        help="the filter runs' length [s] (default: the scenario's)",
    )
    parser.add_argument(
        "--soak", type=float, default=0.0, metavar="SECONDS", help="the soak table: a run this long"
    )
    parser.add_argument(
        "--settings",
        type=config_path,
        default=None,
        help="the --config of the filter and soak runs ('default', the default: the shipped settings)",
    )
    parser.add_argument("--profile", action="store_true")
    parser.add_argument("--loop-runs", type=int, default=3, help="runs of the loop alone for the table")
    return parser.parse_args()


def config_path(text: str) -> Path | None:
    return None if text == "default" else Path(text)


def udp_runs(args) -> list[dict]:
    """One UDP run per --config, each again in real time with --realtime."""
    runs = []
    for config in args.config or [None]:
        runs.append(udp(args.duration, args.out, config))
        if args.realtime:
            name = f"{config.stem if config else 'default'}-realtime"
            runs.append(udp(args.duration, args.out, config, name=name, **REALTIME))
    return runs


def main():
    args = arguments()
    if args.profile:
        print(json.dumps(profile()))
        return 0
    args.out.mkdir(parents=True, exist_ok=True)
    results: dict = {
        "bench": "drive",
        "scenario": "panda_wipe",
        "duration_s": args.duration,
        "targets": TARGETS,
    }
    if args.transport in ("memq", "both"):
        results["memq"] = memq(args.duration, args.out)
    if args.transport in ("udp", "both"):
        results["udp_runs"] = udp_runs(args)
        results["udp"] = results["udp_runs"][0]
    if args.loop_runs:
        results["loop_alone"] = loop_alone(args.loop_runs)
        for run in [results.get("memq"), *results.get("udp_runs", [])]:
            if run:
                run.update(ratios(run, results["loop_alone"]))
    (args.out / "table.md").write_text(table(results))
    print(table(results), end="")
    for run in results.get("udp_runs", []):
        print(summary(run))
    if args.filter:
        duration = args.filter_duration or load_scenario("panda_wipe", config=args.settings).duration
        results["filter"] = filter_runs(duration, args.out, args.settings, args.realtime)
        write_table(args.out / "filter", filter_table(results["filter"], args.settings, args.realtime))
    if args.soak:
        results["soak"] = soak(args.soak, args.out, args.settings)
        write_table(args.out / "soak", soak_table(results["soak"]))
    main_run = results.get("udp") if results.get("udp", {}).get("cpu_p50_us") else results.get("memq", {})
    results["cpu_p50_us"], results["cpu_p999_us"] = main_run.get("cpu_p50_us"), main_run.get("cpu_p999_us")
    print(json.dumps(results, default=str))
    return 0


def write_table(folder: Path, text: str) -> None:
    folder.mkdir(parents=True, exist_ok=True)
    (folder / "table.md").write_text(text)
    print(text, end="")


if __name__ == "__main__":
    sys.exit(main())
