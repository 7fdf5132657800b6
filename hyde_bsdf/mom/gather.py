"""Waiting on an executor without hanging: results of independent tasks, with liveness checks.

:func:`gather` submits one task per item to a :class:`concurrent.futures.Executor` (a process
pool, :class:`~hyde_bsdf.mom.solver.SerialExecutor`, or a dask.distributed
``client.get_executor()``) and collects the results in order.  It never waits blindly: it waits
at most ``POLL_S`` seconds at a time, and between waits it

* checks that the executor can still run tasks -- a dask cluster whose client is no longer
  running, or which has had no worker for ``NO_WORKER_GRACE_S`` seconds (its only worker died),
  is dead; a process pool that lost a worker process is broken;
* enforces the caller's ``timeout`` (seconds without any task finishing), if given;
* reports a heartbeat line through the caller's callback every ``HEARTBEAT_S`` seconds without
  a finished task (the module itself prints nothing).

A dead or broken executor, a task killed with its worker, or a timeout ends in
:class:`ExecutorError`, a one-line message that names the executor (``dask cluster at
tcp://...``, ``process pool of 4 workers``) and how many tasks had finished; the tasks still
pending are cancelled.  An exception raised *by a task* reaches the caller unchanged.
"""
from __future__ import annotations

import concurrent.futures as cf
import time

from hyde_bsdf.errors import UsageError, shorten
from hyde_bsdf.progress import as_callback

__all__ = ["gather", "ExecutorError", "check_executor", "describe_executor", "executor_problem",
           "POLL_S", "HEARTBEAT_S", "NO_WORKER_GRACE_S"]

#: longest single wait on the executor before the liveness checks run again (seconds)
POLL_S = 2.0
#: a heartbeat line every this many seconds in which no task finished (when a heartbeat callback is given)
HEARTBEAT_S = 30.0
#: a dask cluster with no worker for this long is dead (an adaptive cluster may sit at zero
#: workers briefly while it scales up)
NO_WORKER_GRACE_S = 60.0


class ExecutorError(RuntimeError):
    """The executor cannot finish the work: dead cluster, broken pool, killed worker or timeout."""


def _dask_client(executor):
    """The dask.distributed Client behind a ``client.get_executor()``, else None."""
    if type(executor).__module__.split(".")[0] != "distributed":
        return None
    return getattr(executor, "_client", None)


def check_executor(executor):
    """``executor`` if it is None or a ``concurrent.futures.Executor`` (a dask one included);
    a one-line UsageError otherwise -- a raw dask ``Client`` names ``client.get_executor()``."""
    if executor is None or isinstance(executor, cf.Executor):
        return executor
    kind = type(executor)
    if kind.__module__.split(".")[0] == "distributed" and kind.__name__ == "Client":
        raise UsageError("executor is a dask Client; pass client.get_executor() (a concurrent.futures "
                         "executor) instead")
    raise UsageError(f"executor must be a concurrent.futures.Executor (or None), got {kind.__name__}")


def describe_executor(executor) -> str:
    """A short name for messages: 'dask cluster at tcp://host:8786', 'process pool of 4 workers', ..."""
    client = _dask_client(executor)
    if client is not None:
        try:
            address = client.scheduler.address
        except AttributeError:
            address = None
        return f"dask cluster at {address}" if address else "dask cluster"
    if isinstance(executor, cf.ProcessPoolExecutor):
        return f"process pool of {getattr(executor, '_max_workers', '?')} workers"
    if isinstance(executor, cf.ThreadPoolExecutor):
        return f"thread pool of {getattr(executor, '_max_workers', '?')} threads"
    return f"executor {type(executor).__name__}"


def executor_problem(executor):
    """None while ``executor`` can run tasks; else (kind, sentence) saying why it cannot.

    kind is 'dead' (no recovery: fail at once) or 'no-workers' (a dask cluster with no worker
    right now: fail after NO_WORKER_GRACE_S).
    """
    if getattr(executor, "_broken", False):          # ProcessPoolExecutor after a worker died
        return "dead", f"it is broken ({executor._broken})"
    if getattr(executor, "_shutdown_thread", False) or getattr(executor, "_shutdown", False):
        return "dead", "it was shut down"
    client = _dask_client(executor)
    if client is None:
        return None
    status = str(getattr(client, "status", "running"))
    if status not in ("running", "newly-created"):
        return "dead", f"its client is {status} (the scheduler is unreachable or was closed)"
    try:
        try:
            info = client.scheduler_info(n_workers=0)  # totals only: cheap on a big cluster
        except TypeError:                             # distributed < 2025: no n_workers argument
            info = client.scheduler_info()
    except Exception as exc:  # noqa: BLE001 -- any failure to reach the scheduler is reported
        return "dead", f"its scheduler does not answer ({type(exc).__name__}: {exc})"
    n_workers = info.get("n_workers")
    if n_workers is None:
        n_workers = len(info.get("workers", {}))
    if n_workers == 0:
        return "no-workers", "it has no worker (the only worker died or was never started)"
    return None


def _is_executor_failure(exc) -> bool:
    """A failure of the executor rather than of the task: a broken pool, a killed dask worker, a cancel."""
    if isinstance(exc, (cf.BrokenExecutor, cf.CancelledError)):
        return True
    return type(exc).__name__ in ("KilledWorker", "FutureCancelledError") \
        and type(exc).__module__.split(".")[0] == "distributed"


class _Run:
    """The tasks of one :func:`gather` call: their futures, results and count done, and the one-line
    ExecutorError that names the executor (its pending tasks cancelled)."""

    def __init__(self, executor, total, what, label):
        self.executor, self.what, self.label = executor, what, label
        self.total = total
        self.results = [None] * self.total
        self.futures = {}
        self.pending = set()
        self.done_count = 0
        self.name = describe_executor(executor)
        self.no_worker_since = None

    def fail(self, sentence):
        """Cancel the pending tasks; the ExecutorError to raise."""
        for fut in self.pending:
            fut.cancel()
        return ExecutorError(f"{self.label}: the {self.name} {sentence}; {self.done_count} of {self.total} "
                             f"{self.what}s had finished")

    def submit(self, fn, items):
        """One task per item; an executor that refuses them is an ExecutorError."""
        try:
            for i, item in enumerate(items):
                fut = self.executor.submit(fn, item)
                self.futures[fut] = i
                self.pending.add(fut)
        except (cf.BrokenExecutor, RuntimeError) as exc:
            raise self.fail(f"refused the {self.what}s ({type(exc).__name__}: {exc})") from None

    def collect(self, done, on_done, on_result=None):
        """Store the results of the finished futures; a task's own exception is re-raised unchanged (the others
        cancelled), a failure of the executor (killed worker, broken pool) is an ExecutorError."""
        for fut in done:
            try:
                self.results[self.futures[fut]] = fut.result()
            except BaseException as exc:
                if _is_executor_failure(exc):
                    detail = str(exc).strip().splitlines()[0] if str(exc).strip() else "no detail"
                    raise self.fail(f"lost {self.what} {self.futures[fut] + 1} ({type(exc).__name__}: "
                                    f"{detail})") from None
                for other in self.pending:
                    other.cancel()
                raise
            self.done_count += 1
            if on_result is not None:
                on_result(self.futures[fut], self.results[self.futures[fut]])
            if on_done is not None:
                on_done(self.done_count)

    def check_alive(self, now):
        """ExecutorError if the executor is dead, or has had no worker for NO_WORKER_GRACE_S seconds."""
        problem = executor_problem(self.executor)
        if problem is None:
            self.no_worker_since = None
            return
        kind, sentence = problem
        if kind == "dead":
            raise self.fail(f"cannot finish the work: {sentence}")
        self.no_worker_since = now if self.no_worker_since is None else self.no_worker_since
        if now - self.no_worker_since >= NO_WORKER_GRACE_S:
            raise self.fail(f"is dead: {sentence}; no worker for {now - self.no_worker_since:.0f} s")


def gather(executor, fn, items, *, timeout=None, on_done=None, heartbeat=None, what="task",
           label="hyde-bsdf", on_result=None):
    """[fn(item) for item in items], run on ``executor``, without ever waiting blindly.

    Parameters
    ----------
    executor : concurrent.futures.Executor (a caller's executor is not shut down here).
    fn, items : the task function and its arguments, one task per item.
    timeout : float or None, seconds without any task finishing after which the run is
        given up (None: no limit while the executor is alive).
    on_done : callable(done_count) or None, called after every finished task (progress).
    heartbeat : callable(message) or None (or a bool, as :func:`hyde_bsdf.progress.as_callback`
        reads it: True is lines on stderr), called every HEARTBEAT_S seconds in which nothing
        finished with one line naming the executor and the tasks done.
    what, label : words for the messages ('partition', 'mom').
    on_result : callable(index, result) or None, called with each task's result as it finishes (in the
        order they finish: a caller checkpoints there, so that a killed run keeps what was done).

    Raises
    ------
    ExecutorError (one line naming the executor) for a dead cluster, a broken pool, a task
    killed with its worker, or the timeout; the pending tasks are cancelled.  A task's own
    exception is re-raised unchanged.
    """
    if timeout is not None and not (timeout > 0):
        raise UsageError(f"timeout must be > 0 seconds or None, got {shorten(timeout)}")
    beat = as_callback(heartbeat, prefix="")
    items = list(items)
    run = _Run(executor, len(items), what, label)
    run.submit(fn, items)
    last_done = last_beat = time.monotonic()
    while run.pending:
        step = POLL_S if timeout is None else min(POLL_S, max(0.01, timeout - (time.monotonic() - last_done)))
        done, run.pending = cf.wait(run.pending, timeout=step, return_when=cf.FIRST_COMPLETED)
        run.collect(done, on_done, on_result)
        now = time.monotonic()
        if done:
            last_done = last_beat = now
            run.no_worker_since = None
            continue
        run.check_alive(now)
        idle = now - last_done
        if timeout is not None and idle >= timeout:
            raise run.fail(f"finished no {what} for {idle:.0f} s (timeout={timeout:g} s)")
        if beat is not None and now - last_beat >= HEARTBEAT_S:
            last_beat = now
            beat(f"{label}: waiting on the {run.name}: {run.done_count}/{run.total} {what}s done, "
                 f"none finished for {idle:.0f} s")
    return run.results
