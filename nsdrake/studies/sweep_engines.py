"""Where a sweep's runs are simulated: in this process, in a pool of local processes,
or on a Dask distributed cluster.

Every engine takes the runs' plain parameters (:meth:`nsdrake.studies.sweep_spec.Run.task`: the
scenario as YAML text, its index, its seed) and yields plain results as runs finish,
in any order: a Drake diagram cannot be pickled, so each worker builds its own. A run
that raises is a failed result (``nsdrake.studies.sweep_worker.simulate_run`` catches it); a worker
process that dies is a failed result too, marked ``crashed`` (tried again on resume),
and the other runs go on.
"""

from __future__ import annotations

import logging
import multiprocessing
import signal
from collections.abc import Iterator
from multiprocessing.connection import wait

from nsdrake.studies.compare import start_quietly
from nsdrake.studies.sweep_spec import SweepError
from nsdrake.studies.sweep_worker import crash_if_asked, simulate_run

ENGINES = ("process", "dask")
DASK_MISSING = "--engine dask needs Dask: pip install 'nsdrake[cluster]'"


CONNECT_TIMEOUT = 10.0  # [s] a --scheduler has this long to answer as a Dask scheduler


def check_engine(engine: str, scheduler: str | None) -> None:
    """One line, before anything runs: the engine exists and can be imported, and a
    ``scheduler`` is a Dask scheduler that answers (:func:`check_scheduler`)."""
    if engine not in ENGINES:
        raise SweepError(f"--engine must be one of {', '.join(ENGINES)}, got {engine!r}")
    if scheduler is not None and engine != "dask":
        raise SweepError("--scheduler needs --engine dask")
    if engine == "dask":
        try:
            import dask.distributed  # noqa: F401
        except ImportError:
            raise SweepError(DASK_MISSING) from None
    if scheduler is not None:
        check_scheduler(scheduler, CONNECT_TIMEOUT)


def check_scheduler(address: str, timeout: float) -> dict:
    """The identity of the Dask scheduler at ``address``; SweepError (one line) if the
    address is malformed, nothing answers within ``timeout`` seconds, or what answers is
    not a Dask scheduler (a server of another kind, which Dask's own client would wait on
    for ever: its handshake has no time limit)."""
    import asyncio

    from distributed.comm import connect

    async def identity() -> object:
        comm = await connect(address, timeout=timeout)
        try:
            await comm.write({"op": "identity", "reply": True})
            return await comm.read()
        finally:
            comm.abort()

    where = f"--scheduler {_short(address)}"
    try:
        answer = asyncio.run(asyncio.wait_for(identity(), timeout))
    except (asyncio.TimeoutError, TimeoutError):
        raise SweepError(f"{where}: no Dask scheduler answered within {timeout:g} s") from None
    except ValueError as e:  # malformed: Dask's address parser says why
        raise SweepError(f"{where}: not a scheduler address ({_short(e)}); e.g. tcp://HOST:8786") from None
    except Exception as e:  # refused, unreachable, or a server that speaks another protocol
        raise SweepError(f"{where}: cannot reach a Dask scheduler: {_short(e)}") from None
    if not isinstance(answer, dict) or answer.get("type") != "Scheduler":
        raise SweepError(
            f"{where}: the server there is not a Dask scheduler (it answered {_short(repr(answer))})"
        )
    return answer


def _short(text, length: int = 160) -> str:
    line = " ".join(str(text).split())
    return line if len(line) <= length else line[: length - 1] + "…"


def results(tasks: list[dict], *, engine: str, jobs: int, scheduler: str | None = None) -> Iterator[dict]:
    """The result of every task, in the order they finish."""
    if not tasks:
        return iter(())
    if engine == "dask":
        return _dask(tasks, jobs, scheduler)
    if jobs <= 1:
        return (simulate_run(task) for task in tasks)
    return _processes(tasks, jobs)


def _crashed(task: dict, why: str) -> dict:
    return {
        "index": task["index"],
        "status": "failed",
        "reason": why,
        "metrics": {},
        "traces_csv": None,
        "crashed": True,
    }


# --- local processes ------------------------------------------------------------------


def _worker(conn) -> None:
    """A pool process: runs the tasks it is sent, one at a time, until told to stop."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # Ctrl-C is the parent's to handle
    while True:
        try:
            task = conn.recv()
        except EOFError:  # the parent is gone
            return
        if task is None:
            return
        crash_if_asked(task)
        conn.send(simulate_run(task))


class _Slot:
    def __init__(self, ctx):
        self.conn, child = ctx.Pipe()
        self.process = ctx.Process(target=_worker, args=(child,), daemon=True, name="nsdrake-sweep-worker")
        start_quietly(self.process)  # Ctrl-C while it starts: no traceback from it
        child.close()
        self.task: dict | None = None

    def stop(self) -> None:
        try:
            if self.process.is_alive() and self.task is None:
                self.conn.send(None)
                self.process.join(timeout=5)
        except (OSError, BrokenPipeError):
            pass
        if self.process.is_alive():
            self.process.terminate()
            self.process.join(timeout=5)
        self.conn.close()


def _processes(tasks: list[dict], jobs: int) -> Iterator[dict]:
    """A pool of ``jobs`` spawned processes that knows which run each process holds, so
    that a process that dies fails that run alone and is replaced (multiprocessing.Pool
    hangs, and concurrent.futures breaks the whole pool, when a worker dies)."""
    ctx = multiprocessing.get_context("spawn")
    pending = list(reversed(tasks))
    slots = [_Slot(ctx) for _ in range(min(jobs, len(tasks)))]
    try:
        while pending or any(s.task is not None for s in slots):
            for s in slots:
                if s.task is None and pending:
                    s.task = pending.pop()
                    s.conn.send(s.task)
            busy = [s for s in slots if s.task is not None]
            ready = set(wait([s.conn for s in busy] + [s.process.sentinel for s in busy]))
            for i, s in enumerate(slots):
                if s.task is None or (s.conn not in ready and s.process.sentinel not in ready):
                    continue
                task, s.task = s.task, None
                try:
                    if not s.conn.poll():
                        raise EOFError
                    result = s.conn.recv()
                except (EOFError, OSError):
                    s.process.join(timeout=5)
                    yield _crashed(task, f"the worker process died (exit code {s.process.exitcode})")
                    s.stop()
                    slots[i] = _Slot(ctx)
                    continue
                yield result
    finally:
        for s in slots:
            s.stop()


# --- Dask -----------------------------------------------------------------------------


def _dask_task(task: dict) -> dict:
    crash_if_asked(task)
    return simulate_run(task)


def _dask(tasks: list[dict], jobs: int, scheduler: str | None) -> Iterator[dict]:
    """On the cluster at ``scheduler``, or on a LocalCluster of ``jobs`` single-threaded
    worker processes started for the sweep. The workers import nsdrake: on a cluster of
    your own, install it there too."""
    import dask
    from dask.distributed import Client, LocalCluster, as_completed

    cluster = None
    # A run that kills its worker is retried once, then reported (Dask's default is 3).
    with dask.config.set({"distributed.scheduler.allowed-failures": 1}):
        if scheduler is None:
            cluster = LocalCluster(
                n_workers=jobs,
                threads_per_worker=1,
                processes=True,
                dashboard_address=None,
                silence_logs=logging.ERROR,
            )
        client = Client(cluster if cluster is not None else scheduler, timeout=CONNECT_TIMEOUT)
    try:
        futures = {
            # The key names the run's scenario and seed: two sweeps sharing a scheduler
            # share only runs that are the same simulation.
            client.submit(_dask_task, task, key=f"nsdrake-sweep-{task['hash']}", pure=False): task
            for task in tasks
        }
        for future in as_completed(futures):
            task = futures[future]
            try:
                yield future.result()
            except Exception as e:  # the worker died (KilledWorker) or the task could not run
                why = " ".join(str(e).split())[:200]
                yield _crashed(task, f"the Dask worker failed: {type(e).__name__}: {why}")
            finally:
                future.release()
    finally:
        client.close()
        if cluster is not None:
            cluster.close()
