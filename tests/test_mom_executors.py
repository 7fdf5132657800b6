"""mom.scatter never waits forever on an executor (issue 15, item 8).

Checks that every wait on an executor ends: a dask cluster whose only worker died, a process pool
whose worker was killed and an executor that never finishes a task each end in one
:class:`ExecutorError` line naming the executor, within seconds (liveness checks and the grace
period are shortened here); a task's own exception reaches the caller unchanged; the heartbeat
line reaches the progress callback (stderr for mom.scatter's default) while nothing finishes.
"""
import concurrent.futures as cf
import multiprocessing
import os
import time

import pytest

from hyde_bsdf import mom
from hyde_bsdf.mom import gather as gather_mod
from hyde_bsdf.mom.gather import ExecutorError, gather

ARGS = (20.0, 2, 0.0, 1.0, 0.0, 0.0)   # a flat plate, 2 partitions of 10 wavelengths: milliseconds of work


@pytest.fixture
def fast_checks(monkeypatch):
    monkeypatch.setattr(gather_mod, "POLL_S", 0.05)
    monkeypatch.setattr(gather_mod, "NO_WORKER_GRACE_S", 0.5)
    monkeypatch.setattr(gather_mod, "HEARTBEAT_S", 0.2)


class NeverExecutor(cf.Executor):
    """Accepts tasks and never runs them (a hung remote service)."""

    def submit(self, fn, /, *args, **kwargs):
        return cf.Future()


def _die(_):
    os._exit(3)


def _fail(_):
    raise ArithmeticError("task's own error")


def test_dead_dask_cluster_is_an_error_naming_it(fast_checks):
    distributed = pytest.importorskip("distributed")
    with distributed.LocalCluster(n_workers=1, processes=False, threads_per_worker=1,
                                  dashboard_address=None) as cluster, distributed.Client(cluster) as client:
        client.sync(cluster.workers[0].close)          # the only worker dies
        t0 = time.monotonic()
        with pytest.raises(ExecutorError) as err:
            mom.scatter(*ARGS, pts_per_wl=6, executor=client.get_executor(), progress=False)
        took = time.monotonic() - t0
    msg = str(err.value)
    assert "\n" not in msg
    assert "dask cluster at " in msg and cluster.scheduler_address in msg
    assert "no worker" in msg and "0 of 2 partitions had finished" in msg
    assert took < 10.0


def test_killed_process_pool_worker_is_an_error_naming_the_pool(fast_checks):
    with cf.ProcessPoolExecutor(1, mp_context=multiprocessing.get_context("fork")) as pool:
        with pytest.raises(ExecutorError, match=r"^mom: the process pool of 1 workers lost partition 1 "
                                                r"\(BrokenProcessPool"):
            gather(pool, _die, [0], what="partition", label="mom")


def test_timeout_without_progress(fast_checks, capsys):
    t0 = time.monotonic()
    with pytest.raises(ExecutorError, match=r"executor NeverExecutor finished no partition for \d+ s "
                                            r"\(timeout=0.6 s\); 0 of 2 partitions had finished"):
        mom.scatter(*ARGS, pts_per_wl=6, executor=NeverExecutor(), timeout=0.6)
    assert time.monotonic() - t0 < 5.0
    assert "mom.scatter: waiting on the executor NeverExecutor: 0/2 partitions done" in capsys.readouterr().err


def test_task_errors_pass_through_and_bad_timeout_is_refused():
    with pytest.raises(ArithmeticError, match="task's own error"):
        gather(mom.SerialExecutor(), _fail, [0, 1])
    with pytest.raises(ValueError, match="timeout must be finite and > 0"):
        mom.scatter(*ARGS, pts_per_wl=6, executor=mom.SerialExecutor(), timeout=0)
    res = mom.scatter(*ARGS, pts_per_wl=6, executor=mom.SerialExecutor(), timeout=30, progress=False)
    assert res.sigma.shape == (1, 1)


def test_heartbeat_goes_only_to_the_callback(fast_checks, capsys):
    """The library prints nothing: gather's heartbeat (every HEARTBEAT_S = 0.2 s here without a finished task)
    reaches the caller's callback; without one there is no line at all."""
    lines = []
    with pytest.raises(ExecutorError, match="timeout=0.6 s"):
        gather(NeverExecutor(), _fail, [0, 1], timeout=0.6, heartbeat=lines.append, what="partition", label="mom")
    assert lines and lines[0].startswith("mom: waiting on the executor NeverExecutor: 0/2 partitions done")
    with pytest.raises(ExecutorError):
        gather(NeverExecutor(), _fail, [0], timeout=0.3, what="partition", label="mom")
    assert capsys.readouterr().err == ""
