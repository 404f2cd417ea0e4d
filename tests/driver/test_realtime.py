"""The real-time mode (nsdrake/driver/realtime.py): what it sets in the loop thread, read
back from the OS independently of the module (os.sched_getscheduler, os.sched_getaffinity,
/proc/self/status's VmLck), restored afterwards; and each refusal's one line, before
anything is simulated or sent (the refusals of the OS itself: a process without root's
rights, made here by dropping them, which only root can do)."""

from __future__ import annotations

import ctypes
import gc
import os
import resource
import subprocess
import sys
import threading
from pathlib import Path

import pytest

from nsdrake.cli import main
from nsdrake.driver.realtime import RealtimeSettings, realtime_mode, realtime_problem, realtime_settings
from nsdrake.experiment.scenario import load_scenario

ROOT = Path(__file__).resolve().parents[2]
CORE = max(os.sched_getaffinity(0))  # the last core this process may run on
PRIORITY = 37  # none of the defaults: a priority read back as 37 was set from the settings
SETTINGS = RealtimeSettings(priority=PRIORITY, core=CORE)
REFUSED_HERE = realtime_problem(SETTINGS)
needs_realtime = pytest.mark.skipif(
    REFUSED_HERE is not None, reason=f"this OS refuses the real-time mode here: {REFUSED_HERE}"
)


def vm_lck_kb() -> int:
    """The process's locked memory [kB], read from /proc/self/status here (not by the module)."""
    line = next(x for x in Path("/proc/self/status").read_text().splitlines() if x.startswith("VmLck:"))
    return int(line.split()[1])


def os_settings(tid: int = 0) -> tuple:
    """(policy, priority, cores) of thread ``tid`` (0: the calling one), from the OS."""
    return os.sched_getscheduler(tid), os.sched_getparam(tid).sched_priority, os.sched_getaffinity(tid)


def in_a_thread(body):
    """``body()``'s return value, run on a new thread (as the loop runs on the main one of
    its process, the test's main thread stays an ordinary one to compare with)."""
    out = {}

    def run():
        out["value"] = body()

    thread = threading.Thread(target=run)
    thread.start()
    thread.join()
    return out["value"]


@needs_realtime
def test_the_thread_runs_at_the_settings_asked_and_gets_its_own_back():
    """Inside the block: this thread SCHED_FIFO at the priority asked, on the core asked, the
    process's memory locked, the collector off; the process's main thread untouched (a
    mode applied to the process, sched_setscheduler(getpid()), changes the main thread
    instead); after it, every one restored. Catches a setting skipped or applied to the
    wrong thread, a priority or core not the one asked, and one not restored."""
    main_tid = threading.main_thread().native_id
    before_main = os_settings(main_tid)

    def body():
        before = os_settings(), vm_lck_kb(), gc.isenabled()
        with realtime_mode(SETTINGS) as applied:
            inside = os_settings(), vm_lck_kb(), gc.isenabled(), os_settings(main_tid)
        return before, inside, (os_settings(), vm_lck_kb(), gc.isenabled()), applied

    before, inside, after, applied = in_a_thread(body)
    (policy, priority, cores), locked, collecting, main_inside = inside
    assert (policy, priority, cores) == (os.SCHED_FIFO, PRIORITY, {CORE})
    assert locked > 100_000  # [kB] pydrake's libraries and more: the whole process, not a page
    assert not collecting
    assert main_inside == before_main
    assert after == before
    assert before[0][0] == os.SCHED_OTHER and before[1] == 0
    assert (applied.policy, applied.priority, applied.cores) == ("SCHED_FIFO", PRIORITY, (CORE,))


CORES = sorted(os.sched_getaffinity(0))  # every core this process may run on, core 0 first when allowed


@needs_realtime
@pytest.mark.parametrize("core", [*CORES, -1], ids=[*(f"core {c}" for c in CORES), "not pinned (-1)"])
def test_each_core_is_pinned_and_only_minus_one_is_not(core):
    """Every core this process may run on, core 0 among them, pins the thread to that core
    alone (read back from the OS); -1, the one value that means "not pinned", leaves the
    thread on the cores it had (issue 46, mistake 3: the value beside the sentinel).
    Catches a core taken as a truth value (core 0 silently unpinned: `--realtime-core 0`
    runs on every core) or -1 pinned to some core. Memory not locked: not what is tested."""
    settings = RealtimeSettings(priority=PRIORITY, core=core, lock_memory=False)

    def body():
        before = os_settings()
        with realtime_mode(settings) as applied:
            inside = os_settings()
        return before, inside, os_settings(), applied

    before, inside, after, applied = in_a_thread(body)
    cores = before[2] if core == -1 else {core}
    assert inside == (os.SCHED_FIFO, PRIORITY, cores) and applied.cores == tuple(sorted(cores))
    assert after == before


@pytest.mark.parametrize("core", [0, CORES[-1], -1])
def test_a_core_flag_of_zero_is_a_core_not_an_absent_flag(core):
    """`--realtime-core 0` and driver.realtime.core 0 choose core 0, named after where they
    came from, like any other core; without --realtime the flag 0 is refused as any flag
    is (it would be ignored). Catches a flag read as a truth value (0 dropped for the
    scenario's -1, or let through without --realtime)."""
    from nsdrake.driver.realtime import RealtimeError
    from nsdrake.experiment.driver_config import RealtimeConfig

    flag = realtime_settings(RealtimeConfig(), flag=True, core=core)
    assert (flag.core, flag.name("core")) == (core, "--realtime-core")
    scenario = realtime_settings(RealtimeConfig(enabled=True, core=core))
    assert (scenario.core, scenario.name("core")) == (core, "driver.realtime.core")
    over = realtime_settings(RealtimeConfig(enabled=True, core=5), core=core)
    assert (over.core, over.name("core")) == (core, "--realtime-core")
    with pytest.raises(RealtimeError, match="--realtime-core: applies with --realtime"):
        realtime_settings(RealtimeConfig(), core=core)


@needs_realtime
def test_the_settings_are_restored_when_the_block_raises():
    """A fault inside the loop (an exception through the block) still restores the thread.
    Catches restoring only on a normal exit."""

    def body():
        before = os_settings(), vm_lck_kb()
        with pytest.raises(RuntimeError, match="fault"), realtime_mode(SETTINGS):
            raise RuntimeError("fault")
        return before, (os_settings(), vm_lck_kb())

    before, after = in_a_thread(body)
    assert after == before


def probe_drive(scenario, realtime):
    """A lockstep drive whose loop thread reads its OS settings at every tick."""
    from nsdrake.driver.run import prepare

    drive = prepare(scenario, realtime_rate=0.0)
    seen = []
    tick = drive.loop.tick

    def reading_tick():
        seen.append((os_settings(), vm_lck_kb(), gc.isenabled()))
        tick()

    drive.loop.tick = reading_tick
    return drive.run(realtime=realtime), seen


@pytest.mark.slow  # builds the Panda's station and simulated driver (seconds)
@needs_realtime
def test_the_drive_loop_ticks_in_real_time_and_records_it():
    """`nsdrake drive`'s loop (Drive.run): every tick in the real-time mode asked, the same in
    timing.json's ``realtime``, the thread restored when the drive ends; the scenario's own
    driver.realtime applies when no settings are given. Catches the hook around something
    other than the loop, or a drive that ignores the scenario's section."""
    scenario = load_scenario("panda_wipe", duration=0.03)

    def body():
        before = os_settings(), vm_lck_kb()
        run, seen = probe_drive(scenario, SETTINGS)
        return before, run, seen, (os_settings(), vm_lck_kb())

    before, run, seen, after = in_a_thread(body)
    assert run.failure is None and len(seen) == 30
    settings = {(policy, priority, frozenset(cores)) for (policy, priority, cores), _, _ in seen}
    assert settings == {(os.SCHED_FIFO, PRIORITY, frozenset({CORE}))}
    assert all(locked > 100_000 and not collecting for _, locked, collecting in seen)
    assert run.timing["realtime"] | {"memory_locked_kb": 0} == {
        "policy": "SCHED_FIFO", "priority": PRIORITY, "cores": [CORE], "memory_locked_kb": 0,
        "collector_off": True, "other_threads": 0,
    }  # fmt: skip
    assert after == before
    scenario.driver.realtime.enabled, scenario.driver.realtime.priority = True, PRIORITY + 1
    _, seen = in_a_thread(lambda: probe_drive(scenario, None))
    assert {s[0][:2] for s in seen} == {(os.SCHED_FIFO, PRIORITY + 1)}


class ReadingStop:
    """A stop request that reads the serving thread's OS settings each period it is asked,
    and asks to stop after ``periods``."""

    def __init__(self, periods: int):
        self.seen, self.periods = [], periods

    @property
    def requested(self) -> bool:
        self.seen.append((os_settings(), vm_lck_kb(), gc.isenabled()))
        return len(self.seen) > self.periods


@pytest.mark.slow  # builds the Panda's simulated driver (seconds)
@needs_realtime
def test_the_simulated_driver_serves_in_real_time():
    """`nsdrake sim-driver`'s loop (serve_simulated_driver) in the real-time mode asked at
    every period, restored after. Catches the hook missing or around the set-up only."""
    from pydrake.lcm import DrakeLcm

    from nsdrake.driver.serve import serve_simulated_driver

    scenario = load_scenario("panda_wipe")
    stop = ReadingStop(20)

    def body():
        before = os_settings(), vm_lck_kb()
        served = serve_simulated_driver(scenario, DrakeLcm("memq://"), stop=stop, realtime=SETTINGS)
        return before, served, (os_settings(), vm_lck_kb())

    before, served, after = in_a_thread(body)
    assert len(stop.seen) == 21
    for (policy, priority, cores), locked, collecting in stop.seen:
        assert (policy, priority, cores, collecting) == (os.SCHED_FIFO, PRIORITY, {CORE}, False)
        assert locked > 100_000
    assert served.realtime["policy"] == "SCHED_FIFO" and served.realtime["cores"] == [CORE]
    assert after == before


def refused(argv, capsys, tmp_path) -> str:
    """The one line a refused command prints; nothing may have been written."""
    out = tmp_path / "out"
    try:
        code = main([*argv, "--out", str(out)] if argv[0] == "drive" else argv)
    except SystemExit as e:
        code = e.code
    captured = capsys.readouterr()
    assert code == 2 and not out.exists()
    lines = captured.err.strip().splitlines()
    assert len(lines) == 1, captured.err
    return lines[0]


NO_CORE = max(os.sched_getaffinity(0)) + 1


RANGE = "must be an integer from 1 to 99"


@pytest.mark.parametrize(
    ("argv", "line"),
    [
        (["--realtime", "--realtime-priority", "0"], f"--realtime-priority: {RANGE}"),
        (["--realtime", "--realtime-priority", "100"], f"--realtime-priority: {RANGE}"),
        (["--realtime", "--realtime-core", str(NO_CORE)], f"--realtime-core: no core {NO_CORE} for this"),
        (["--realtime", "--realtime-core", "-2"], "--realtime-core: must be a core's number"),
        (["--realtime-core", "0"], "--realtime-core: applies with --realtime"),
        (["--realtime-priority", "50"], "--realtime-priority: applies with --realtime"),
    ],
)
@pytest.mark.parametrize("command", ["drive", "sim-driver"])
def test_a_setting_out_of_range_is_refused_in_one_line(command, argv, line, capsys, tmp_path):
    """Both commands, before anything is built or sent (sim-driver's memq:// is refused later,
    so its real-time line shows the check comes first; drive's --out folder is never made).
    Catches a priority outside SCHED_FIFO's 1-99 (0 is SCHED_OTHER's), a core this process
    may not run on, and a flag that would be ignored without --realtime."""
    bus = ["--simulated-driver"] if command == "drive" else ["--lcm", "memq://"]
    line_printed = refused([command, "panda_wipe", *bus, *argv], capsys, tmp_path)
    assert line_printed.startswith(f"nsdrake: error: {line}")


def test_the_scenario_s_settings_are_checked_with_the_scenario(tmp_path, capsys):
    """driver.realtime's priority out of range is the scenario's problem, named by its field."""
    config = tmp_path / "rt.yaml"
    config.write_text("driver:\n  realtime: {enabled: true, priority: 120}\n")
    line = refused(["drive", "panda_wipe", "--simulated-driver", "--config", str(config)], capsys, tmp_path)
    assert "driver.realtime.priority: must be an integer from 1 to 99 (SCHED_FIFO's range), got 120" in line
    assert realtime_settings(load_scenario("panda_wipe").driver.realtime) is None  # off unless enabled


PR_CAPBSET_DROP, CAP_SYS_NICE, CAP_IPC_LOCK = 24, 23, 14  # <linux/prctl.h>, <linux/capability.h>


def without_the_rights(argv, capabilities) -> subprocess.CompletedProcess:
    """``nsdrake ARGV`` in a process that lacks rights a real-time loop needs: the
    ``capabilities`` dropped from its bounding set before it starts (so root's process
    lacks them, as an ordinary user's), its rtprio limit 0 and its memlock limit 64 kB
    (where a capability is missing, the OS allows by these limits, as it does a user)."""

    def drop():
        libc = ctypes.CDLL(None, use_errno=True)
        for cap in capabilities:
            if libc.prctl(PR_CAPBSET_DROP, cap, 0, 0, 0) != 0:
                raise OSError(ctypes.get_errno(), "prctl(PR_CAPBSET_DROP)")
        resource.setrlimit(resource.RLIMIT_RTPRIO, (0, 0))
        resource.setrlimit(resource.RLIMIT_MEMLOCK, (64 * 1024, 64 * 1024))

    return subprocess.run(
        [sys.executable, "-m", "nsdrake", *argv],
        cwd=ROOT,
        capture_output=True,
        text=True,
        preexec_fn=drop,
        timeout=300,
    )


@pytest.mark.skipif(os.geteuid() != 0, reason="dropping root's rights needs root")
@pytest.mark.parametrize(
    ("capabilities", "line"),
    [
        (
            (CAP_SYS_NICE, CAP_IPC_LOCK),
            "--realtime-priority: this user may not run a thread at SCHED_FIFO priority 80 "
            "(Operation not permitted; its rtprio limit is 0)",
        ),
        (
            (CAP_IPC_LOCK,),
            "--realtime: this user may not lock the process's memory (mlockall needs root or "
            "CAP_IPC_LOCK, or no memlock limit; this one is 64 kB",
        ),
    ],
)
def test_what_the_os_refuses_a_user_is_refused_in_one_line(capabilities, line, tmp_path):
    """As a process without the right to a real-time priority (no CAP_SYS_NICE, rtprio
    limit 0), then as one with it but without the right to lock memory (no CAP_IPC_LOCK,
    memlock limit 64 kB): `nsdrake drive --realtime` ends with one line
    naming what the OS refused, exit 2, before the drive is built (no folder). Catches a
    permission found only inside the loop (a traceback, or a drive that silently runs as an
    ordinary thread), and a memory lock nobody checked."""
    out = tmp_path / "out"
    done = without_the_rights(
        ["drive", "panda_wipe", "--simulated-driver", "--realtime", "--out", str(out)], capabilities
    )
    assert done.returncode == 2, done.stderr
    assert done.stderr.strip().splitlines() == [done.stderr.strip()]
    assert done.stderr.startswith(f"nsdrake: error: {line}")
    assert not out.exists()


@needs_realtime
def test_memory_locked_before_the_bus_is_not_locked_again_by_the_loop(monkeypatch):
    """The commands lock the process's memory before the bus subscribes (memory_locked);
    the loop's realtime_mode inside it must not call mlockall again (faulting in the whole
    process while LCM's receive thread waits: statuses queued behind the loop's ready(),
    measured to stop a real-time drive at its first status), nor unlock it when the loop
    ends; the outer block unlocks. Catches a second mlockall, and an unlock by the inner block."""
    from nsdrake.driver import realtime

    calls = []
    real = realtime._libc

    class Counting:
        def __init__(self):
            self.libc = real()

        def mlockall(self, flags):
            calls.append("mlockall")
            return self.libc.mlockall(flags)

        def munlockall(self):
            calls.append("munlockall")
            return self.libc.munlockall()

    monkeypatch.setattr(realtime, "_libc", Counting)

    def body():
        with realtime.memory_locked(SETTINGS):
            locked = vm_lck_kb()
            with realtime_mode(SETTINGS):
                inside = list(calls)
            after_loop = vm_lck_kb(), list(calls)
        return locked, inside, after_loop, vm_lck_kb()

    locked, inside, (after_loop_kb, after_loop_calls), after = in_a_thread(body)
    assert locked > 100_000 and inside == ["mlockall"]
    assert after_loop_kb > 100_000 and after_loop_calls == ["mlockall"]
    assert after == 0 and calls == ["mlockall", "munlockall"]


def a_bus_thread():
    """A thread standing in for LCM's receive thread (a UDP bus may not be made outside a
    namespace, and memq:// starts none): its id, the thread, and the event that ends it.
    The test hides it from threading.enumerate, as a thread a C library started is."""
    ready, done = threading.Event(), threading.Event()
    box = {}

    def run():
        box["tid"] = threading.get_native_id()
        ready.set()
        done.wait()

    thread = threading.Thread(target=run)
    thread.start()
    ready.wait()
    return box["tid"], thread, done


@needs_realtime
@pytest.mark.parametrize("core", sorted({CORES[0], CORE}), ids=lambda c: f"core {c}")
def test_threads_the_bus_started_follow_the_loop_s_mode(monkeypatch, core):
    """Inside realtime_process (entered before the bus is made), the threads started since
    (LCM's receive thread) get the loop's priority and core with it, and theirs back after;
    a thread that was there before (numpy's BLAS worker) keeps its own. On the first core
    this process may run on (core 0) and on the last. Catches the bus's thread left an
    ordinary one (statuses delivered in bursts behind the machine's other work), every
    thread of the process made real-time, and core 0 taken for "not pinned"."""
    from nsdrake.driver import realtime

    # memory not locked: mlockall of the whole process costs seconds and is not what is
    # tested here (test_memory_locked_before_the_bus_is_not_locked_again_by_the_loop is)
    settings = RealtimeSettings(priority=PRIORITY, core=core, lock_memory=False)
    before_tid, before_thread, before_done = a_bus_thread()
    with realtime.realtime_process(settings):
        bus_tid, bus_thread, bus_done = a_bus_thread()
        hidden = {before_thread, bus_thread}
        enumerate_ = threading.enumerate
        monkeypatch.setattr(threading, "enumerate", lambda: [t for t in enumerate_() if t not in hidden])
        own = os_settings(bus_tid), os_settings(before_tid)

        def body():
            with realtime_mode(settings) as applied:
                return applied, os_settings(bus_tid), os_settings(before_tid)

        applied, bus_inside, before_inside = in_a_thread(body)
        bus_after = os_settings(bus_tid)
    for done, thread in ((bus_done, bus_thread), (before_done, before_thread)):
        done.set()
        thread.join()
    assert bus_inside == (os.SCHED_FIFO, PRIORITY, {core}) and applied.other_threads == 1
    assert before_inside == own[1] and bus_after == own[0]
