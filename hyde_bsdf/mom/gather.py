"""Waiting on an executor without hanging: results of independent tasks, with liveness checks.

:func:`gather` submits one task per item to a :class:`concurrent.futures.Executor` (a process
pool, :class:`~hyde_bsdf.mom.solver.SerialExecutor`, or a dask.distributed
``client.get_executor()``) and collects the results in order.  It waits at most ``POLL_S``
seconds at a time, and between waits it checks that the executor can still run tasks (a dask
cluster whose client is closed, or which has had no worker for ``NO_WORKER_GRACE_S`` seconds, is
dead; a process pool that lost a worker is broken), enforces ``timeout`` (seconds without any task
finishing; by default ``HYDE_BSDF_TASK_TIMEOUT``, 3600 s: :func:`hyde_bsdf.resources.wait_limit`),
asks a dask scheduler nothing without a limit (:func:`scheduler_identity`), and reports a heartbeat line every ``HEARTBEAT_S`` seconds without a
finished task.  A dead executor, a task killed with its worker, or the timeout ends in one
:class:`ExecutorError` line naming the executor and how many tasks had finished; the pending
tasks are cancelled.  An exception raised *by a task* reaches the caller unchanged.
:func:`end_pool` ends a pool the caller made without waiting on a task that never finishes.
"""
from __future__ import annotations

import concurrent.futures as cf
import time

from hyde_bsdf.errors import UsageError, shorten
from hyde_bsdf.progress import as_callback
from hyde_bsdf.resources import wait_limit

__all__ = ["gather", "end_pool", "ExecutorError", "check_executor", "scheduler_identity", "POLL_S", "HEARTBEAT_S",
           "NO_WORKER_GRACE_S"]

#: longest single wait on the executor before the liveness checks run again (seconds)
POLL_S = 2.0
#: a heartbeat line every this many seconds in which no task finished (when a heartbeat callback is given)
HEARTBEAT_S = 30.0
#: a dask cluster with no worker for this long is dead (an adaptive cluster may sit at zero
#: workers briefly while it scales up)
NO_WORKER_GRACE_S = 60.0


class ExecutorError(RuntimeError):
    """The executor cannot finish the work: dead cluster, broken pool, killed worker or timeout."""


def _is_dask(kind) -> bool:
    return kind.__module__.split(".")[0] == "distributed"


def check_executor(executor):
    """``executor`` if it is None or a ``concurrent.futures.Executor`` (a dask one included);
    a one-line UsageError otherwise -- a raw dask ``Client`` names ``client.get_executor()``."""
    if executor is None or isinstance(executor, cf.Executor):
        return executor
    if _is_dask(type(executor)) and type(executor).__name__ == "Client":
        raise UsageError("executor is a dask Client; pass client.get_executor() (a concurrent.futures "
                         "executor) instead")
    raise UsageError(f"executor must be a concurrent.futures.Executor (or None), got {type(executor).__name__}")


def _client(executor):
    """The dask.distributed Client behind a ``client.get_executor()``, else None."""
    return getattr(executor, "_client", None) if _is_dask(type(executor)) else None


def _name(executor) -> str:
    """'dask cluster at tcp://host:8786', 'process pool of 4 workers', ... for messages."""
    client = _client(executor)
    if client is not None:
        address = getattr(getattr(client, "scheduler", None), "address", None)
        return f"dask cluster at {address}" if address else "dask cluster"
    if isinstance(executor, (cf.ProcessPoolExecutor, cf.ThreadPoolExecutor)):
        kind = "process pool" if isinstance(executor, cf.ProcessPoolExecutor) else "thread pool"
        return f"{kind} of {getattr(executor, '_max_workers', '?')} workers"
    return f"executor {type(executor).__name__}"


def _problem(executor):
    """None while ``executor`` can run tasks; else (dead, sentence): dead False means a dask
    cluster without a worker right now (dead after NO_WORKER_GRACE_S)."""
    if getattr(executor, "_broken", False):          # ProcessPoolExecutor after a worker died
        return True, f"it is broken ({executor._broken})"
    if getattr(executor, "_shutdown_thread", False) or getattr(executor, "_shutdown", False):
        return True, "it was shut down"
    client = _client(executor)
    if client is None:
        return None
    status = str(getattr(client, "status", "running"))
    if status not in ("running", "newly-created"):
        return True, f"its client is {status} (the scheduler is unreachable or was closed)"
    try:
        info = scheduler_identity(client, n_workers=0)  # totals only: cheap on a big cluster
    except Exception as exc:  # noqa: BLE001 -- any failure to reach the scheduler is reported
        return True, f"its scheduler does not answer ({type(exc).__name__}: {exc})"
    workers = info.get("n_workers", len(info.get("workers", {})))
    return (False, "it has no worker (the only worker died or was never started)") if workers == 0 else None


def scheduler_identity(client, **kwargs) -> dict:
    """The dask scheduler's answer to ``identity`` (its workers, their threads), waited for at most
    ``HYDE_BSDF_CONNECT_TIMEOUT`` seconds (a TimeoutError naming it beyond)."""
    seconds, name = wait_limit("connect")
    try:
        try:
            return client.sync(client.scheduler.identity, **kwargs, callback_timeout=seconds)
        except TypeError:                         # distributed < 2025: no n_workers argument
            return client.sync(client.scheduler.identity, callback_timeout=seconds)
    except TimeoutError:
        raise TimeoutError(f"no answer within {seconds:g} s ({name})") from None


def _executor_failure(exc) -> bool:
    """A failure of the executor rather than of the task: a broken pool, a killed dask worker, a cancel."""
    return isinstance(exc, (cf.BrokenExecutor, cf.CancelledError)) or (
        type(exc).__name__ in ("KilledWorker", "FutureCancelledError") and _is_dask(type(exc)))


def gather(executor, fn, items, *, timeout=None, on_done=None, heartbeat=None, what="task", label="hyde-bsdf",
           on_result=None):
    """[fn(item) for item in items], run on ``executor`` (not shut down here), never waiting blindly.

    ``timeout``: seconds without any task finishing after which the run is given up (None:
    ``HYDE_BSDF_TASK_TIMEOUT``, default 3600 s); ``on_done(done_count)`` after every finished task;
    ``heartbeat``: a progress callback (as :func:`hyde_bsdf.progress.as_callback` reads it) called
    every HEARTBEAT_S seconds in which nothing finished; ``what``, ``label``: words for the
    messages ('partition', 'mom'); ``on_result(index, result)`` with each task's result as it
    finishes (a caller checkpoints there, so that a killed run keeps what was done).  Raises
    ExecutorError (module docstring).
    """
    if timeout is not None and not (timeout > 0):
        raise UsageError(f"timeout must be > 0 seconds or None, got {shorten(timeout)}")
    timeout, setting = (timeout, "timeout") if timeout is not None else wait_limit("task")
    beat, name, items = as_callback(heartbeat, prefix=""), _name(executor), list(items)
    futures, results, done_count = {}, [None] * len(items), 0

    def fail(sentence):
        for fut in futures:
            fut.cancel()
        return ExecutorError(f"{label}: the {name} {sentence}; {done_count} of {len(items)} {what}s had finished")

    try:
        futures = {executor.submit(fn, item): i for i, item in enumerate(items)}
    except (cf.BrokenExecutor, RuntimeError) as exc:
        raise fail(f"refused the {what}s ({type(exc).__name__}: {exc})") from None
    pending, last_done, last_beat, no_worker_since = set(futures), time.monotonic(), time.monotonic(), None
    while pending:
        step = min(POLL_S, max(0.01, timeout - (time.monotonic() - last_done)))
        done, pending = cf.wait(pending, timeout=step, return_when=cf.FIRST_COMPLETED)
        for fut in done:
            try:
                results[futures[fut]] = fut.result()
            except BaseException as exc:
                if not _executor_failure(exc):
                    fail("")                      # cancels the others; the task's own exception goes on
                    raise
                detail = (str(exc).strip().splitlines() or ["no detail"])[0]
                raise fail(f"lost {what} {futures[fut] + 1} ({type(exc).__name__}: {detail})") from None
            done_count += 1
            if on_result is not None:
                on_result(futures[fut], results[futures[fut]])
            if on_done is not None:
                on_done(done_count)
        now = time.monotonic()
        if done:
            last_done = last_beat = now
            no_worker_since = None
            continue
        problem = _problem(executor)
        if problem is not None and problem[0]:
            raise fail(f"cannot finish the work: {problem[1]}")
        if problem is None or no_worker_since is None:
            no_worker_since = None if problem is None else now
        if no_worker_since is not None and now - no_worker_since >= NO_WORKER_GRACE_S:
            raise fail(f"is dead: {problem[1]}; no worker for {now - no_worker_since:.0f} s")
        idle = now - last_done
        if idle >= timeout:
            raise fail(f"finished no {what} for {idle:.0f} s ({setting}={timeout:g} s)")
        if beat is not None and now - last_beat >= HEARTBEAT_S:
            last_beat = now
            beat(f"{label}: waiting on the {name}: {done_count}/{len(items)} {what}s done, "
                 f"none finished for {idle:.0f} s")
    return results


def end_pool(executor, finished: bool) -> None:
    """Shut down a pool the package made for a call: once every task ``finished``, waiting for its
    workers to exit; otherwise (a time-out, a lost task, an exception) its workers are killed first,
    so a task that never ends holds neither this call nor the interpreter's exit (which joins the
    pool).  The workers are taken before the shutdown, which forgets them."""
    workers = [] if finished else list((getattr(executor, "_processes", None) or {}).values())
    for proc in workers:
        proc.kill()
    executor.shutdown(wait=True if finished else bool(workers), cancel_futures=True)
