"""The ``nsdrake`` command line.

    nsdrake run SCENARIO|FILE.yaml [--config FILE.yaml] [--out DIR] [--duration SECONDS] [--overwrite]
                          [--meshcat] [--no-replay]
    nsdrake compare FAMILY [--config FILE.yaml] [--out DIR] [--duration SECONDS] [--jobs N] [--overwrite]
                           [--variant-timeout SECONDS]
    nsdrake sweep SPEC [--out DIR] [--jobs N] [--engine process|dask] [--scheduler ADDRESS] [--overwrite]
                       [--max-runs N]
    nsdrake drive SCENARIO (--lcm URL | --simulated-driver) [--config FILE.yaml] [--out DIR]
                           [--duration SECONDS] [--overwrite] [--realtime-rate RATE]
                           [--realtime [--realtime-priority N] [--realtime-core N]]
    nsdrake sim-driver SCENARIO --lcm URL [--config FILE.yaml] [--duration SECONDS]
                                [--realtime [--realtime-priority N] [--realtime-core N]]
    nsdrake list

Every input problem ends with one line on stderr, "nsdrake: error: …", and exit
status 2, before any simulation starts; a run that fails (a bound missed, a divergence,
a fault on the wire) exits 1, Ctrl-C 130 (keeping what was computed, marked interrupted).
"""

from __future__ import annotations

import argparse
import contextlib
import math
import os
import sys
import time
from pathlib import Path

from nsdrake import ctrl_c
from nsdrake.experiment.output import (
    OutputFolderError,
    default_output_folder,
    prepare_output_folder,
    release_unused,
)
from nsdrake.experiment.scenario import ScenarioError, load_scenario, scenario_label, shipped_scenarios
from nsdrake.reporting.metrics import metric_line
from nsdrake.reporting.progress import Progress
from nsdrake.reporting.run_folder import check_scenario, run_to_folder
from nsdrake.station.visualization import start_meshcat
from nsdrake.studies.compare import (
    VARIANT_TIMEOUT,
    check_variants,
    load_family,
    run_family,
    shipped_families,
)
from nsdrake.studies.sweep import sweep_command
from nsdrake.studies.sweep_engines import ENGINES
from nsdrake.studies.sweep_spec import MAX_RUNS, shipped_sweeps


class _Parser(argparse.ArgumentParser):
    def error(self, message):  # one line, exit 2, like every other input error
        self.exit(2, f"nsdrake: error: {message}\n")


def _duration(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"--duration must be a number of seconds, got '{text}'") from None
    if not math.isfinite(value) or value <= 0:
        raise argparse.ArgumentTypeError(f"--duration must be > 0 seconds, got '{text}'")
    return value


def build_parser() -> argparse.ArgumentParser:
    parser = _Parser(
        prog="nsdrake", description="Null-space velocity control (Nemec & Zlajpah 2000) on Drake."
    )
    sub = parser.add_subparsers(dest="command", required=True, parser_class=_Parser)
    _add_run_parser(sub)
    compare = sub.add_parser("compare", help="run a family of variants and tabulate the paper's claims")
    compare.add_argument("family", help=f"a shipped family: {', '.join(shipped_families())}")
    compare.add_argument(
        "--config", type=Path, help="YAML file applied to every variant (before its own switch)"
    )
    compare.add_argument(
        "--out", type=Path, help="output folder (default: runs/compare-FAMILY, never overwritten)"
    )
    compare.add_argument("--duration", type=_duration, help="simulated time of every variant [s]")
    compare.add_argument("--jobs", type=_jobs, default=min(2, os.cpu_count() or 1), help="parallel processes")
    compare.add_argument(
        "--overwrite",
        action="store_true",
        help="replace the files an earlier nsdrake run wrote in --out (never others)",
    )
    compare.add_argument(
        "--variant-timeout",
        type=_seconds,
        default=VARIANT_TIMEOUT,
        help=f"stop a variant still running after this many seconds (default {VARIANT_TIMEOUT:g})",
    )
    sweep = sub.add_parser("sweep", help="run a scenario over a grid or random samples of its fields")
    sweep.add_argument("spec", help=f"a shipped sweep ({', '.join(shipped_sweeps())}) or a spec file")
    sweep.add_argument(
        "--out", type=Path, help="output folder (default: runs/sweep-NAME); reuse it to resume"
    )
    sweep.add_argument("--jobs", type=_jobs, default=min(2, os.cpu_count() or 1), help="parallel runs")
    sweep.add_argument("--engine", choices=ENGINES, default="process", help="local processes, or Dask")
    sweep.add_argument("--scheduler", help="address of a Dask scheduler (default: a local cluster)")
    sweep.add_argument("--overwrite", action="store_true", help="replace the runs of another sweep in --out")
    sweep.add_argument(
        "--max-runs",
        type=_jobs_like("--max-runs"),
        default=MAX_RUNS,
        help=f"refuse a sweep of more runs than this (default {MAX_RUNS})",
    )
    _add_drive_parsers(sub)
    sub.add_parser("list", help="list the shipped scenarios, families and sweeps")
    return parser


def _add_run_parser(sub) -> None:
    run = sub.add_parser("run", help="run a scenario and write traces, metrics and plots")
    run.add_argument(
        "scenario", help=f"a shipped scenario ({', '.join(shipped_scenarios())}) or a scenario file's path"
    )
    run.add_argument("--config", type=Path, help="YAML file whose fields override the scenario's")
    run.add_argument(
        "--out", type=Path, help="output folder (default: runs/SCENARIO, the file's stem, never overwritten)"
    )
    run.add_argument("--duration", type=_duration, help="simulated time [s], overrides the scenario")
    run.add_argument(
        "--overwrite",
        action="store_true",
        help="replace the files an earlier nsdrake run wrote in --out (never others)",
    )
    run.add_argument(
        "--meshcat", action="store_true", help="show the run live in Meshcat on localhost (prints the URL)"
    )
    run.add_argument("--no-replay", action="store_true", help="do not record replay.html")


def _add_drive_parsers(sub) -> None:
    drive = sub.add_parser(
        "drive", help="run a scenario's controller behind a Franka Panda's LCM driver (or the simulated one)"
    )
    drive.add_argument("scenario", help="a 7-joint Panda's scenario: shipped (panda_wipe) or a file's path")
    bus = drive.add_mutually_exclusive_group(required=True)
    bus.add_argument("--lcm", metavar="URL", help="the LCM URL the robot's driver talks on")
    bus.add_argument(
        "--simulated-driver",
        action="store_true",
        help="run the simulated driver in this process, both sides over memq://",
    )
    drive.add_argument("--config", type=Path, help="YAML file whose fields override the scenario's")
    drive.add_argument(
        "--out", type=Path, help="output folder (default: runs/drive-SCENARIO, never overwritten)"
    )
    drive.add_argument("--duration", type=_duration, help="time to drive [s], overrides the scenario")
    drive.add_argument(
        "--overwrite", action="store_true", help="replace the files an earlier nsdrake run wrote in --out"
    )
    drive.add_argument(
        "--realtime-rate",
        type=_rate,
        default=1.0,
        help="with --simulated-driver: the driver's pace against the wall clock "
        "(1: real time; 0: as fast as possible; at least a control period a second)",
    )
    _add_realtime_options(drive, "the loop thread", " (overrides driver.realtime)")
    sim = sub.add_parser("sim-driver", help="run the simulated driver alone on an LCM bus, at real time")
    sim.add_argument("scenario", help="a 7-joint Panda's scenario: shipped (panda_wipe) or a file's path")
    sim.add_argument("--lcm", metavar="URL", required=True, help="the LCM URL the controller talks on")
    sim.add_argument("--config", type=Path, help="YAML file whose fields override the scenario's")
    sim.add_argument("--duration", type=_duration, help="time to serve after the first command [s]")
    sim.add_argument(
        "--expire-sec",
        type=_positive("--expire-sec"),
        help="a command older than this [s] is dropped and the robot damps (drake-franka-driver's "
        "--expire_sec; default: the scenario's driver.expire_sec, 0.05 as shipped)",
    )
    sim.add_argument(
        "--low-pass-freq",
        type=_positive("--low-pass-freq"),
        default=30.0,
        help="libfranka's torque low-pass cutoff [Hz] (drake-franka-driver's --low_pass_freq, default 30; "
        "1000 turns it off)",
    )
    sim.add_argument(
        "--no-rate-limit", action="store_true", help="turn libfranka's torque rate limiter (1000 N m/s) off"
    )
    _add_realtime_options(sim, "the driver's thread", "")


def _add_realtime_options(parser, thread: str, overrides: str) -> None:
    parser.add_argument(
        "--realtime",
        action="store_true",
        help=f"run {thread} in real time: SCHED_FIFO, memory locked, the collector off "
        f"(root or CAP_SYS_NICE and CAP_IPC_LOCK){overrides}",
    )
    parser.add_argument(
        "--realtime-priority",
        type=int,
        metavar="N",
        help=f"with --realtime: the SCHED_FIFO priority, 1-99 (default 80){overrides}",
    )
    parser.add_argument(
        "--realtime-core",
        type=int,
        metavar="N",
        help=f"with --realtime: the core {thread} is pinned to{overrides}",
    )


def _positive(option: str):
    def parse(text: str) -> float:
        try:
            value = float(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{option} must be a number, got '{text}'") from None
        if not math.isfinite(value) or value <= 0:
            raise argparse.ArgumentTypeError(f"{option} must be a finite number > 0, got '{text}'")
        return value

    return parse


def _rate(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"--realtime-rate must be a number, got '{text}'") from None
    if not math.isfinite(value) or value < 0:
        raise argparse.ArgumentTypeError(f"--realtime-rate must be >= 0, got '{text}'")
    return value


def _jobs_like(option: str):
    """A parser of whole numbers >= 1 for ``option``."""

    def parse(text: str) -> int:
        try:
            value = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{option} must be a whole number, got '{text}'") from None
        if value < 1:
            raise argparse.ArgumentTypeError(f"{option} must be >= 1, got '{text}'")
        return value

    return parse


_jobs = _jobs_like("--jobs")


def _seconds(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"--variant-timeout must be a number of seconds, got '{text}'"
        ) from None
    if not math.isfinite(value) or value <= 0:
        raise argparse.ArgumentTypeError(f"--variant-timeout must be > 0 seconds, got '{text}'")
    return value


def _load(args, *, notes: bool = True):
    """The scenario the command line names (a shipped one or a file, --config, --duration),
    validated; what the loader did that changes it (a table dropped) printed, one line each
    (``notes`` False: the caller says them once its own checks passed, :func:`_say_notes`)."""
    scenario = load_scenario(args.scenario, config=args.config, duration=args.duration)
    if notes:
        _say_notes(scenario)
    return scenario


def _say_notes(scenario) -> None:
    for note in scenario.notes:
        print(f"nsdrake: note: {note}")


def _run(args) -> int:
    scenario = _load(args, notes=False)
    check_scenario(scenario)  # model files, joint names, checks' needs: fail before anything is written
    _say_notes(scenario)  # a refused scenario says its one line only
    label = scenario_label(args.scenario)
    with _claimed(args.out, label, args.overwrite, computes=False) as out:
        try:
            meshcat = _live_meshcat() if args.meshcat else None
        except RuntimeError as e:  # e.g. no free port in Meshcat's range
            print(f"nsdrake: error: cannot start Meshcat: {' '.join(str(e).split())}", file=sys.stderr)
            return 2
        print(f"nsdrake: running {args.scenario} ({scenario.duration:g} s simulated) into {out}/")
        runs = 2 if scenario.report.compare_without_null_space_task else 1
        progress = Progress(label, 1.0, simulated=runs * scenario.duration)
        answer = ctrl_c.current()

        def report(done: float) -> None:  # each hundredth: a Ctrl-C kept through a compile stops it here
            if answer is not None:
                answer.report()
            progress(done)

        try:
            result = run_to_folder(scenario, out, progress=report, replay=not args.no_replay, meshcat=meshcat)
        finally:
            progress.end_line()
    if result.interrupted:
        print(f"nsdrake: {result.failure}; the run so far is in {out}/, marked interrupted", file=sys.stderr)
        return INTERRUPTED
    if answer is not None and answer.pending:  # held through a compile after the run's end
        print(f"nsdrake: interrupted (Ctrl-C) as the run ended; the whole run is in {out}/", file=sys.stderr)
        return INTERRUPTED
    for m in result.metrics:
        print(metric_line(m))
    for note in result.notes:
        print(f"nsdrake: {note}")
    if result.failure:
        print(f"nsdrake: error: {scenario.source}: {result.failure}", file=sys.stderr)
    files = ", ".join(sorted(p.name for p in out.iterdir()))
    print(f"nsdrake: wrote {out}/: {files}")
    print(f"nsdrake: report: open {out / 'report.html'} in a browser (works offline)")
    if meshcat is not None and sys.stdin.isatty():
        input(f"nsdrake: the replay stays in Meshcat at {meshcat.web_url()}; press Enter to quit ")
    return 0 if result.passed else 1


def _compare(args) -> int:
    family = load_family(args.family)
    check_variants(family, args.config, args.duration)  # every input error before any folder or simulation
    if args.config is not None:  # what the overlay did to the family's scenario (a table dropped)
        for note in load_scenario(family.scenario, config=args.config, validated=False).notes:
            print(f"nsdrake: note: {note}")
    with _claimed(args.out, f"compare-{args.family}", args.overwrite) as out:
        print(f"nsdrake: running {len(family.variants)} variants of {args.family} into {out}/")
        progress = Progress(args.family, 1.0)
        with progress:  # the heartbeat: a variant reports only when it ends
            result = run_family(
                family,
                out,
                config=args.config,
                duration=args.duration,
                jobs=args.jobs,
                isolate=True,  # a variant that crashes its process becomes a failed row, even with --jobs 1
                progress=progress,
                variant_timeout=args.variant_timeout,
                checked=True,
            )
        progress.end_line()
    if result.interrupted:
        print(
            f"nsdrake: interrupted; the table and each variant's traces so far are in {out}/ "
            "(unfinished rows marked interrupted)",
            file=sys.stderr,
        )
        return INTERRUPTED
    print((out / "table.md").read_text())
    listed = [name for name in ("table.md", "table.csv") if (out / name).exists()]
    files = ", ".join(listed + [p.name for p in sorted(out.glob("*.png"))])
    print(f"nsdrake: wrote {out}/: {files}, variants/*/traces.csv")
    for name, note in result.notes.items():
        print(f"nsdrake: variant '{name}': {note}")
    for name, reason in result.failures.items():
        print(f"nsdrake: variant '{name}' {reason}", file=sys.stderr)
    if result.failures:
        print(f"nsdrake: {len(result.failures)} of {len(family.variants)} variants failed", file=sys.stderr)
        return 1
    return 0


def _lcm(url: str):
    """The LCM bus at ``url``; one line (ScenarioError) if it cannot be opened."""
    from nsdrake.driver.bus import BusError, open_bus

    try:
        return open_bus(url)
    except BusError as e:
        raise ScenarioError(f"--lcm: {e}") from None


def _bus(url: str):
    """The controller side's bus at ``url`` (the ``lcm`` package, nsdrake/driver/bus.py)."""
    from nsdrake.driver.bus import BusError, LcmBus

    try:
        return LcmBus(url)
    except BusError as e:
        raise ScenarioError(f"--lcm: {e}") from None


def _drive(args) -> int:
    from nsdrake.driver.realtime import realtime_process

    if args.lcm is not None and not args.lcm.strip():
        raise ScenarioError("--lcm: the URL is empty (an unset variable?); give the robot's LCM URL")
    if args.lcm is not None and args.realtime_rate != 1.0:
        raise ScenarioError(
            "--realtime-rate: paces the simulated driver only; the robot's driver keeps its own time"
        )
    scenario = _load(args)
    realtime = _realtime(args, scenario.driver.realtime)
    with realtime_process(realtime):  # before the bus (nsdrake/driver/realtime.py)
        return _drive_locked(args, scenario, realtime)


def _drive_locked(args, scenario, realtime) -> int:
    from nsdrake.driver.run import prepare, write_drive_folder
    from nsdrake.driver.stop import ctrl_c_requests
    from nsdrake.driver.timing import timing_line

    lcm = _bus(args.lcm) if args.lcm else None
    # the simulated robot adds g itself, or (driver.robot_adds_gravity false) its driver removes it first
    drive = prepare(
        scenario, lcm, realtime_rate=args.realtime_rate, robot_adds_gravity=scenario.driver.robot_adds_gravity
    )  # every input error before the folder
    label = scenario_label(args.scenario)
    with _claimed(args.out, f"drive-{label}", args.overwrite) as out:
        where = "the simulated driver over memq://" if lcm is None else f"the driver at {args.lcm}"
        with ctrl_c_requests() as stop:  # from here on Ctrl-C stops the drive, which keeps its folder
            print(f"nsdrake: driving {args.scenario} ({scenario.duration:g} s) against {where} into {out}/")
            progress = Progress(label, 1.0, simulated=scenario.duration)
            try:
                run = drive.run(progress=progress, stop=stop, realtime=realtime)
            finally:
                progress.end_line()
        result = write_drive_folder(run, out)
    if run.interrupted:
        print(f"nsdrake: {timing_line(run.timing)}")
        print(
            f"nsdrake: drive {run.failure}; what was computed is in {out}/, marked interrupted",
            file=sys.stderr,
        )
        return INTERRUPTED
    for m in result.metrics:
        print(metric_line(m))
    print(f"nsdrake: {timing_line(run.timing)}")
    if run.failure:
        print(f"nsdrake: error: {args.scenario}: drive: {run.failure}", file=sys.stderr)
    files = ", ".join(sorted(p.name for p in out.iterdir()))
    print(f"nsdrake: wrote {out}/: {files}")
    return 0 if result.passed else 1


def _sim_driver(args) -> int:
    from nsdrake.driver.controller_side import check_drive_scenario
    from nsdrake.driver.realtime import realtime_process
    from nsdrake.driver.serve import option_problems

    scenario = check_drive_scenario(_load(args))
    for option, problem in option_problems(scenario, args.expire_sec, args.low_pass_freq):
        raise ScenarioError(f"{option}: {problem}")
    realtime = _realtime(args, None)  # the flags only: the scenario's driver.realtime is the controller's
    if args.lcm.startswith("memq://"):
        raise ScenarioError(
            "--lcm: memq:// is a bus inside one process; another process cannot reach the simulated "
            "driver there (nsdrake drive --simulated-driver runs both sides in one process)"
        )
    with realtime_process(realtime):  # before the bus (nsdrake/driver/realtime.py)
        return _serve(args, scenario, realtime)


def _serve(args, scenario, realtime) -> int:
    from nsdrake.driver.serve import SimulatedDriverStopError, serve_simulated_driver
    from nsdrake.driver.stop import ctrl_c_requests

    lcm = _lcm(args.lcm)
    print(f"nsdrake: simulated driver for {args.scenario} on {args.lcm}; serving (Ctrl-C ends)", flush=True)
    progress = Progress(scenario_label(args.scenario), 1.0, simulated=scenario.duration)
    with ctrl_c_requests() as stop:
        try:
            served = serve_simulated_driver(
                scenario,
                lcm,
                expire_sec=args.expire_sec,
                low_pass_freq=args.low_pass_freq,
                rate_limit=not args.no_rate_limit,
                progress=progress,
                stop=stop,
                realtime=realtime,
            )
        except SimulatedDriverStopError as e:
            progress.end_line()
            print(f"nsdrake: simulated driver: {e.result.line()}")
            print(f"nsdrake: simulated driver stopped: {e}", file=sys.stderr)
            return 1
    progress.end_line()
    print(f"nsdrake: simulated driver: {served.line()}")
    if stop.requested:
        print("nsdrake: simulated driver interrupted (Ctrl-C)", file=sys.stderr)
        return INTERRUPTED
    return 0


def _realtime(args, config):
    """The real-time settings of ``--realtime`` and ``config`` (the scenario's
    ``driver.realtime``; None for sim-driver), checked against what the OS allows: one
    line before anything is simulated or sent (nsdrake/driver/realtime.py)."""
    from nsdrake.driver.realtime import RealtimeError, realtime_problem, realtime_settings

    try:
        settings = realtime_settings(
            config, flag=args.realtime, priority=args.realtime_priority, core=args.realtime_core
        )
    except RealtimeError as e:
        raise ScenarioError(str(e)) from None
    problem = settings and realtime_problem(settings)
    if problem:
        raise ScenarioError(problem)
    return settings


INTERRUPTED = ctrl_c.INTERRUPTED


def claim_output_folder(
    out: Path | None, default_name: str, *, overwrite: bool, created: list[Path] | None = None
) -> Path:
    """``--out``, claimed (see nsdrake/experiment/output.py), or without it the first free
    runs/NAME[-k]; the folders made for it are appended to ``created``."""
    if out is None:
        return default_output_folder(default_name, created=created)
    return prepare_output_folder(out, overwrite=overwrite, created=created)


@contextlib.contextmanager
def _claimed(out: Path | None, default_name: str, overwrite: bool, *, computes: bool = True):
    """The claimed output folder; if the command ends (fails, is stopped) before writing
    anything there, the claim is undone and the folders made for it removed. Unless the
    command reports what it computes (``computes`` False: ``run``), a Ctrl-C from the
    claim on is a KeyboardInterrupt even while a kernel compiles (nsdrake/ctrl_c.py)."""
    created: list[Path] = []
    answer = ctrl_c.current()
    folder = claim_output_folder(out, default_name, overwrite=overwrite, created=created)
    if answer is not None:
        answer.claims.append((folder, created))  # a Ctrl-C that exits at once undoes it too
        answer.computed = answer.computed or computes
    try:
        yield folder
    finally:
        release_unused(folder, created)
        if answer is not None:
            answer.claims.remove((folder, created))


BROWSER_WAIT = 60.0  # [s] how long --meshcat waits for a browser on a terminal


def _live_meshcat():
    """Starts Meshcat on localhost and prints its URL; on a terminal, waits (up to
    BROWSER_WAIT) for a browser to connect so that the run is seen from its start."""
    meshcat = start_meshcat(live=True)
    url = meshcat.web_url()
    print(f"nsdrake: Meshcat is at {url}")
    if sys.stdin.isatty():
        print(f"nsdrake: waiting for a browser at {url} (up to {BROWSER_WAIT:g} s) ...", flush=True)
        deadline = time.monotonic() + BROWSER_WAIT
        while meshcat.GetNumActiveConnections() == 0 and time.monotonic() < deadline:
            time.sleep(0.1)
    return meshcat


def main(argv: list[str] | None = None) -> int:
    _never_fail_to_print()
    args = build_parser().parse_args(argv)
    try:
        with ctrl_c.answering() as answer:
            # sweep and sim-driver compute from their start on (a Ctrl-C is a KeyboardInterrupt)
            answer.computed = args.command in ("sweep", "sim-driver")
            return _command(args)
    except KeyboardInterrupt:  # a Ctrl-C the moment the handling was set, before the command began
        print("nsdrake: interrupted", file=sys.stderr)
        return INTERRUPTED


def _command(args) -> int:
    try:
        if args.command == "list":
            print("scenarios (nsdrake run):  " + ", ".join(shipped_scenarios()))
            print("families (nsdrake compare): " + ", ".join(shipped_families()))
            print("sweeps (nsdrake sweep):    " + ", ".join(shipped_sweeps()))
            return 0
        _check_working_directory()
        if args.command == "compare":
            return _compare(args)
        if args.command == "sweep":
            return sweep_command(args)
        if args.command == "drive":
            return _drive(args)
        if args.command == "sim-driver":
            return _sim_driver(args)
        return _run(args)
    except (ScenarioError, OutputFolderError) as e:
        print(f"nsdrake: error: {e}", file=sys.stderr)
        return 2
    except OSError as e:  # e.g. the disk filled up while writing: one line, not a traceback
        print(f"nsdrake: error: {' '.join(str(e).split())}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:  # Ctrl-C outside a simulation (which keeps its traces itself)
        print("nsdrake: interrupted", file=sys.stderr)
        return INTERRUPTED


def _never_fail_to_print() -> None:
    """A terminal or pipe that cannot show a character (an ASCII-only locale, a path of
    undecodable bytes) gets an escape (\\u03a9) instead of ending the command."""
    for stream in (sys.stdout, sys.stderr):
        try:
            stream.reconfigure(errors="backslashreplace")
        except (AttributeError, ValueError):  # not a text stream of io's (a test's capture)
            pass


def _check_working_directory() -> None:
    """Relative paths (runs/, --out, --config) need a working directory that exists."""
    try:
        os.getcwd()
    except FileNotFoundError:
        raise OutputFolderError(
            "the working directory no longer exists (it was deleted or moved); cd into a folder that exists"
        ) from None


if __name__ == "__main__":
    sys.exit(main())
