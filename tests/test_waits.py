"""Every wait bounded (issue 33, item 3): each wait on a network peer, a task or a child process
ends within its limit (hyde_bsdf.resources.TIMEOUTS, HYDE_BSDF_<KIND>_TIMEOUT) with one line that
names the limit and the variable, and SIGTERM ends it at once.

* ``invert --tiles --scheduler tcp://127.0.0.1:PORT`` where a server accepts and never answers
  (was: 240 s without progress, and SIGTERM printed "terminated" but left the process running):
  refused within HYDE_BSDF_CONNECT_TIMEOUT; SIGTERM while it waits: exit 143, one line, no process left;
* a pool whose task never finishes: ExecutorError naming HYDE_BSDF_TASK_TIMEOUT;
* a validation script that hangs: killed, one failed check naming HYDE_BSDF_SCRIPT_TIMEOUT;
* a limit that is not a number of seconds > 0: one line naming the variable.

Cost: about 15 s (one Mitsuba start-up in a child process; the limits are set to fractions of a second).
"""
import concurrent.futures as cf
import os
import signal
import socket
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest
from conftest import scaled

from hyde_bsdf.errors import UsageError

ROOT = Path(__file__).resolve().parent.parent


class MuteServer:
    """Accepts TCP connections on 127.0.0.1 and never answers; ``accepted`` is set on the first."""

    def __init__(self):
        self.sock = socket.socket()
        self.sock.bind(("127.0.0.1", 0))
        self.sock.listen(8)
        self.address = f"tcp://127.0.0.1:{self.sock.getsockname()[1]}"
        self.accepted, self.conns = threading.Event(), []
        threading.Thread(target=self._serve, daemon=True).start()

    def _serve(self):
        while True:
            try:
                self.conns.append(self.sock.accept()[0])
            except OSError:
                return
            self.accepted.set()

    def close(self):
        for c in self.conns + [self.sock]:
            c.close()


@pytest.fixture
def mute():
    server = MuteServer()
    yield server
    server.close()


def _capture(d: Path) -> list:
    """The tiled route's files (test_signals' capture) and the argv naming them."""
    sys.path.insert(0, str(Path(__file__).parent))
    from test_signals import _inputs
    _inputs(d)
    return ["invert", "--maps", "--scene", str(d / "sample.xml"), "--camera", str(d / "camera.json"), "--light",
            str(d / "lights.json"), "--reference", str(d / "ref.exr"), "--tiles", "2", "-o", str(d / "out")]


def test_a_mute_scheduler_is_refused_within_the_connect_limit(mute, tmp_path, monkeypatch, capsys):
    from hyde_bsdf.app.invert import _dask_client

    pytest.importorskip("distributed")
    monkeypatch.setenv("HYDE_BSDF_CONNECT_TIMEOUT", "0.5")
    with pytest.raises(UsageError, match=rf"^--scheduler '{mute.address}': no dask scheduler answers there "
                                         r"\(no answer within 0.5 s \(HYDE_BSDF_CONNECT_TIMEOUT\)\)$"):
        _dask_client(mute.address)
    assert mute.accepted.is_set()


def test_sigterm_ends_the_wait_on_a_mute_scheduler(mute, tmp_path):
    """The run waits on the server (limit 600 s); once the server has accepted its connection, SIGTERM:
    exit 143 with one line, and no process of the run is left."""
    pytest.importorskip("distributed")
    argv = _capture(tmp_path) + ["--scheduler", mute.address]
    proc = subprocess.Popen([sys.executable, "-m", "hyde_bsdf.app.cli", *argv], cwd=ROOT, stdout=subprocess.DEVNULL,
                            stderr=subprocess.PIPE, text=True, start_new_session=True,
                            env={**os.environ, "HYDE_BSDF_CONNECT_TIMEOUT": "600"})
    try:
        assert mute.accepted.wait(scaled(120)), "the run never connected"
        proc.send_signal(signal.SIGTERM)
        err = proc.communicate(timeout=scaled(60))[1]
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
    assert proc.returncode == 143 and err.strip().splitlines() == ["hyde-bsdf invert: terminated (SIGTERM)"], err
    from test_signals import _session
    deadline = time.monotonic() + scaled(20)
    while _session(proc.pid) and time.monotonic() < deadline:
        time.sleep(0.1)
    assert not _session(proc.pid)


def test_a_task_that_never_finishes_ends_at_the_task_limit(monkeypatch):
    from hyde_bsdf.mom.gather import ExecutorError, gather

    monkeypatch.setenv("HYDE_BSDF_TASK_TIMEOUT", "0.3")
    release = threading.Event()
    with cf.ThreadPoolExecutor(1) as pool:
        try:
            with pytest.raises(ExecutorError, match=r"finished no tile for 0 s \(HYDE_BSDF_TASK_TIMEOUT=0.3 s\); "
                                                    r"0 of 1 tiles had finished$"):
                gather(pool, release.wait, [None], what="tile", label="test")
        finally:
            release.set()


def test_a_script_that_hangs_is_killed_at_the_script_limit(tmp_path, monkeypatch):
    from hyde_bsdf.app.report.build import _run_script

    sys.path.insert(0, str(Path(__file__).parent))
    from test_report import _write_fakes
    _write_fakes(tmp_path / "v", {"hang": "signal.pause()"})
    monkeypatch.setenv("HYDE_BSDF_SCRIPT_TIMEOUT", "1")
    checks, _, _ = _run_script(tmp_path / "v" / "hang.py", tmp_path, quick=True)
    assert [c["passed"] for c in checks] == [False]
    assert checks[0]["value"] == f"exit status {-signal.SIGKILL}: timed out after 1 s (HYDE_BSDF_SCRIPT_TIMEOUT): killed"


@pytest.mark.parametrize("value", ["abc", "0", "-3", "inf", "nan"])
def test_a_limit_that_is_not_seconds_is_one_line_naming_the_variable(value, monkeypatch):
    from hyde_bsdf.resources import wait_limit

    monkeypatch.setenv("HYDE_BSDF_TASK_TIMEOUT", value)
    with pytest.raises(UsageError, match=f"^HYDE_BSDF_TASK_TIMEOUT must be a number of seconds > 0, got '{value}'$"):
        wait_limit("task")
