"""A real-time mode for the loop thread on a robot PC (``driver.realtime``, ``--realtime``).

What a real-time loop is given on Linux, as rt-tests' ``cyclictest`` and libfranka's own
examples run theirs:

- the thread at a ``SCHED_FIFO`` priority (``sched_setscheduler``): it runs as soon as it
  is woken, ahead of every ordinary process;
- pinned to one core (``sched_setaffinity``): its caches stay warm, and the other core
  is left to the rest (on a robot PC, the core ``isolcpus`` keeps free);
- the process's memory locked (``mlockall(MCL_CURRENT | MCL_FUTURE)``): no page of it is
  swapped out or faulted in while a command is due;
- Python's garbage collector frozen and off (:func:`nsdrake.driver.timing.collector_paused`).

Each is applied to the thread that enters :func:`realtime_mode` (the loop's) and restored
when it leaves. The commands lock the memory earlier, before the bus is made, with
:func:`realtime_process`, inside which the threads the bus starts (LCM's receive thread,
which the loop waits on) follow the loop's mode too. :func:`realtime_problem` says, in
one line, why the OS will not allow a setting (a priority outside the scheduler's range,
a core this process may not run on, a user without the right to a real-time priority or
to lock memory); the commands call it before anything is simulated or sent. The default
is off: an ordinary PC (no real-time kernel, no root) runs the loop as an ordinary
thread.
"""

from __future__ import annotations

import contextlib
import ctypes
import ctypes.util
import errno
import gc
import os
import resource
import threading
from dataclasses import dataclass

from nsdrake.driver.timing import collector_paused
from nsdrake.experiment.driver_config import RealtimeConfig, realtime_settings_problem
from nsdrake.experiment.scenario import ScenarioError

MCL_CURRENT, MCL_FUTURE = 1, 2  # <sys/mman.h> on Linux
CAP_IPC_LOCK = 14  # <linux/capability.h>: lock memory beyond RLIMIT_MEMLOCK


class RealtimeError(ScenarioError):
    """A real-time setting refused (the commands' input error: one line, exit 2)."""


@dataclass(frozen=True)
class RealtimeSettings:
    """What :func:`realtime_mode` applies: ``priority`` (SCHED_FIFO), ``core`` (-1: not
    pinned), ``lock_memory`` (mlockall). ``names``: what the lines call each setting (the
    scenario's ``driver.realtime.priority`` or the flag ``--realtime-priority``)."""

    priority: int = 80
    core: int = -1
    lock_memory: bool = True
    names: tuple[tuple[str, str], ...] = (
        ("priority", "driver.realtime.priority"),
        ("core", "driver.realtime.core"),
        ("lock_memory", "driver.realtime.lock_memory"),
    )

    def name(self, setting: str) -> str:
        return dict(self.names)[setting]


FLAGS = {"priority": "--realtime-priority", "core": "--realtime-core", "lock_memory": "--realtime"}


def realtime_settings(config: RealtimeConfig | None = None, *, flag: bool = False, priority=None, core=None):
    """The settings to apply, or None (not real-time): the scenario's ``driver.realtime``
    (``config``), turned on by ``flag`` (``--realtime``), its priority and core replaced by
    the flags' (``--realtime-priority``, ``--realtime-core``), each named after where it came
    from. A priority or core flag without real-time on is refused (it would be ignored)."""
    config = config or RealtimeConfig()
    if not (flag or config.enabled):
        for name, value in (("priority", priority), ("core", core)):
            if value is not None:
                raise RealtimeError(
                    f"{FLAGS[name]}: applies with --realtime (or driver.realtime.enabled: true)"
                )
        return None
    names = dict(RealtimeSettings.names) if config.enabled else dict(FLAGS)
    chosen = {"priority": config.priority, "core": config.core}
    for name, value in (("priority", priority), ("core", core)):
        if value is not None:
            chosen[name], names[name] = value, FLAGS[name]
    return RealtimeSettings(lock_memory=config.lock_memory, names=tuple(names.items()), **chosen)


def _cores(cores) -> str:
    return ", ".join(str(c) for c in sorted(cores))


def realtime_problem(settings: RealtimeSettings) -> str | None:
    """Why the OS will not run this process's loop thread with ``settings`` (None: it
    will), in one line: the priority in SCHED_FIFO's range, the core one this process may
    run on, then both tried on a thread of its own that ends at once (what the OS refuses
    there it would refuse in the loop), and the right to lock memory read from the
    process's capabilities and limit."""
    problem = realtime_settings_problem(settings.priority, settings.core)
    if problem:
        return f"{settings.name(problem[0])}: {problem[1]}"
    allowed = os.sched_getaffinity(0)
    if settings.core != -1 and settings.core not in allowed:
        return (
            f"{settings.name('core')}: no core {settings.core} for this process: it may run on cores "
            f"{_cores(allowed)} (os.sched_getaffinity)"
        )
    refused: list[str] = []

    def probe():
        try:
            if settings.core != -1:
                os.sched_setaffinity(0, {settings.core})
            os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(settings.priority))
        except OSError as e:
            refused.append(_refusal(e, settings))

    thread = threading.Thread(target=probe, name="nsdrake-realtime-probe")
    thread.start()
    thread.join()
    if refused:
        return refused[0]
    if settings.lock_memory and not _may_lock_memory():
        limit = resource.getrlimit(resource.RLIMIT_MEMLOCK)[0]
        return (
            f"{settings.name('lock_memory')}: this user may not lock the process's memory (mlockall needs "
            f"root or CAP_IPC_LOCK, or no memlock limit; this one is {limit // 1024} kB: `ulimit -l "
            "unlimited`, or /etc/security/limits.conf); or leave it unlocked "
            "(driver.realtime.lock_memory: false)"
        )
    return None


def _refusal(error: OSError, settings: RealtimeSettings) -> str:
    where = settings.name("priority")
    if error.errno == errno.EPERM:
        limit = resource.getrlimit(resource.RLIMIT_RTPRIO)[0]
        return (
            f"{where}: this user may not run a thread at SCHED_FIFO priority {settings.priority} "
            f"({os.strerror(error.errno)}; its rtprio limit is {limit}): run as root, or give the user "
            f"CAP_SYS_NICE or an rtprio limit ≥ {settings.priority} (/etc/security/limits.conf)"
        )
    return f"{where}: the OS refused SCHED_FIFO priority {settings.priority} on core {settings.core}: {error}"


def _may_lock_memory() -> bool:
    """Whether mlockall of the whole process is allowed: CAP_IPC_LOCK in the effective
    set (root has it), or no limit on locked memory."""
    if resource.getrlimit(resource.RLIMIT_MEMLOCK)[0] == resource.RLIM_INFINITY:
        return True
    with open("/proc/self/status") as status:
        for line in status:
            if line.startswith("CapEff:"):
                return bool(int(line.split()[1], 16) >> CAP_IPC_LOCK & 1)
    return False


def locked_kb() -> int:
    """The process's locked memory [kB] (``VmLck`` of /proc/self/status)."""
    with open("/proc/self/status") as status:
        for line in status:
            if line.startswith("VmLck:"):
                return int(line.split()[1])
    return 0


def _libc():
    libc = ctypes.CDLL(ctypes.util.find_library("c"), use_errno=True)
    libc.mlockall.argtypes, libc.munlockall.argtypes = [ctypes.c_int], []
    return libc


@dataclass
class Applied:
    """What :func:`realtime_mode` set, read back from the OS in the thread that entered it."""

    policy: str = "SCHED_OTHER"
    priority: int = 0
    cores: tuple[int, ...] = ()
    memory_locked_kb: int = 0
    collector_off: bool = False
    other_threads: int = 0  # the process's threads given the same mode (the bus's)

    def as_dict(self) -> dict:
        return {
            "policy": self.policy,
            "priority": self.priority,
            "cores": list(self.cores),
            "memory_locked_kb": self.memory_locked_kb,
            "collector_off": self.collector_off,
            "other_threads": self.other_threads,
        }


POLICY_NAMES = {os.SCHED_OTHER: "SCHED_OTHER", os.SCHED_FIFO: "SCHED_FIFO", os.SCHED_RR: "SCHED_RR"}


def read_back(other_threads: int = 0) -> Applied:
    """The calling thread's scheduling policy, priority and cores, the process's locked
    memory, and whether the collector is off (``other_threads``: how many threads were
    given the same mode)."""
    policy = os.sched_getscheduler(0)
    return Applied(
        policy=POLICY_NAMES.get(policy, str(policy)),
        priority=os.sched_getparam(0).sched_priority,
        cores=tuple(sorted(os.sched_getaffinity(0))),
        memory_locked_kb=locked_kb(),
        collector_off=not gc.isenabled(),
        other_threads=other_threads,
    )


_locked = [0]  # memory_locked blocks open in this process (mlockall is the process's)
_baselines: list[set[int]] = []  # the threads there were when realtime_process was entered


def thread_ids() -> set[int]:
    """The ids of this process's threads (the kernel's, as ``threading.get_native_id``)."""
    return {int(tid) for tid in os.listdir("/proc/self/task")}


@contextlib.contextmanager
def memory_locked(settings: RealtimeSettings | None):
    """The process's memory locked for the block (``mlockall(MCL_CURRENT | MCL_FUTURE)``,
    then ``munlockall``) when ``settings`` ask for it; inside another such block, nothing
    more."""
    if settings is None or not settings.lock_memory or _locked[0]:
        yield
        return
    libc = _libc()
    if libc.mlockall(MCL_CURRENT | MCL_FUTURE) != 0:
        code = ctypes.get_errno()
        raise RealtimeError(f"{settings.name('lock_memory')}: mlockall failed: {os.strerror(code)}")
    _locked[0] += 1
    try:
        yield
    finally:
        _locked[0] -= 1
        libc.munlockall()


@contextlib.contextmanager
def realtime_process(settings: RealtimeSettings | None):
    """What the commands enter before the bus is made (``settings`` None: nothing): the
    process's memory locked (:func:`memory_locked`), and every thread started inside the
    block (the bus's: LCM receives on a thread of its own, which the loop waits for)
    given the loop's real-time mode with it by :func:`realtime_mode`. Both measured as
    needed on a loaded machine: mlockall faults in every page of the process (about
    1.4 GB with pydrake, 0.4 s to seconds) holding its memory map, so that LCM's receive
    thread stops reading; locked at the loop's start, the statuses queued meanwhile came
    out after the loop declared itself ready, stale, then a 300-560 ms jump of the robot's
    clock stopped the drive (2 of 5 runs). And with LCM's thread left an ordinary one, it
    delivered the statuses in bursts behind the machine's other work (386 skipped in 3 s,
    the driver's fresh share 76%)."""
    if settings is None:
        yield
        return
    baseline = thread_ids()
    with memory_locked(settings):
        _baselines.append(baseline)
        try:
            yield
        finally:
            _baselines.pop()


def _follow(settings: RealtimeSettings, restore: contextlib.ExitStack) -> int:
    """The threads a library started inside :func:`realtime_process` (none outside it;
    Python's own threads are not among them) at the loop's priority, on its core;
    restored by ``restore``. Their number."""
    if not _baselines:
        return 0
    python = {thread.native_id for thread in threading.enumerate()}  # the loop's, a progress heartbeat
    others = thread_ids() - _baselines[-1] - python
    for tid in sorted(others):
        try:
            policy, param, cores = (
                os.sched_getscheduler(tid),
                os.sched_getparam(tid),
                os.sched_getaffinity(tid),
            )
            if settings.core != -1:
                os.sched_setaffinity(tid, {settings.core})
            os.sched_setscheduler(tid, os.SCHED_FIFO, os.sched_param(settings.priority))
        except ProcessLookupError:  # the thread ended meanwhile
            continue
        restore.callback(_restore_thread, tid, policy, param, cores)
    return len(others)


def _restore_thread(tid: int, policy: int, param, cores) -> None:
    with contextlib.suppress(ProcessLookupError):
        os.sched_setscheduler(tid, policy, param)
        os.sched_setaffinity(tid, cores)


@contextlib.contextmanager
def realtime_mode(settings: RealtimeSettings | None, *, collector: bool = True):
    """The calling thread in real time for the block (module docstring): memory locked
    first (:func:`memory_locked`, unless locked already), then the core, then SCHED_FIFO,
    the same for the threads started inside :func:`realtime_process`; the collector
    paused when ``collector``. Yields :class:`Applied`, read back from the OS once
    applied. Restored in the reverse order when the block ends, however it ends: the
    policy, priority and cores each thread had, the memory unlocked (if this block locked
    it). ``settings`` None: nothing is changed (yields the thread's own)."""
    if settings is None:
        yield read_back()
        return
    problem = realtime_problem(settings)
    if problem:
        raise RealtimeError(problem)
    policy, param = os.sched_getscheduler(0), os.sched_getparam(0)
    cores = os.sched_getaffinity(0)
    with contextlib.ExitStack() as restore:
        restore.enter_context(collector_paused(collector))
        restore.enter_context(memory_locked(settings))
        if settings.core != -1:
            os.sched_setaffinity(0, {settings.core})
            restore.callback(os.sched_setaffinity, 0, cores)
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(settings.priority))
        restore.callback(os.sched_setscheduler, 0, policy, param)
        followers = _follow(settings, restore)
        yield read_back(followers)
