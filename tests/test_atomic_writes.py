"""Atomic outputs (issue 10): a write that is interrupted -- by an exception, Ctrl-C, SIGTERM or
SIGKILL at any moment -- leaves the previous file intact or the new one complete, never a
truncated file, and (but for SIGKILL) no temporary.

Behaviour checked:
- SIGKILL at random moments while ``write_stokes_exr`` (the writer of ``render`` and ``demo``)
  rewrites a 4 MB Stokes EXR, 24 trials: afterwards the file always reads back with our EXR
  reader and equals, bit for bit, one of the two images the writer alternates between.  A control
  run of the same kills against a plain (non-atomic) OpenEXR write finds truncated files, which
  shows that the kills do land mid-write and that the check would see the damage;
- ``atomic_path`` / ``atomic_open``: an exception inside the block leaves the old file and no
  temporary; the new file gets the permissions ``open`` would give it (0666 & ~umask);
- a real OS limit (RLIMIT_FSIZE: OpenEXR's and matplotlib's own errors) leaves the file being
  written byte for byte, no temporary, and one ``OutputWriteError`` line naming the file;
- temporary names fit NAME_MAX (a 244-character output name works); a name that cannot fit is
  refused by ``check_output_path`` before any work;
- SIGTERM removes the temporaries in flight; the temporaries a SIGKILLed run left are removed by
  the next run's output check, and a live process's are not;
- ``check_output_path`` / ``check_output_dir`` refuse a directory, a parent that is a file,
  ``/proc`` and an unwritable folder with a message naming the path.
"""
import os
import random
import re
import signal
import subprocess
import sys
import textwrap
import threading
from pathlib import Path

import numpy as np
import pytest
from conftest import scaled

from hyde_bsdf.errors import UsageError
from hyde_bsdf.io import atomic
from hyde_bsdf.io.atomic import atomic_open, atomic_path
from hyde_bsdf.io.output_gate import check_output_dir, check_output_path

ROOT = Path(__file__).resolve().parent.parent
SIZE = 256            # 256 x 256 px x 15 float32 channels: ~4 MB, ~0.1-0.2 s per write here

#: A warm parent (numpy, OpenEXR and the writer imported once) forks one writer per trial, so a
#: trial costs a fork instead of a Python start.  The writer rewrites the EXR in a loop,
#: alternating two images (generation g, image g % 2); the test kills it with SIGKILL.
ZYGOTE = textwrap.dedent(r"""
    import os, sys, time
    import numpy as np
    from hyde_bsdf.io.stokes_exr import write_stokes_exr

    def image(parity, size):
        rng = np.random.default_rng(100 + parity)
        return {s: rng.random((size, size, 3), dtype=np.float32) for s in ("S0", "S1", "S2", "S3")}

    def direct_write(path, st, gen):       # the control: a plain, non-atomic write
        import OpenEXR
        chans = {f"{s}.{c}": np.ascontiguousarray(st[s][..., j]) for s in st for j, c in enumerate("RGB")}
        OpenEXR.File({"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage,
                      "hyde_bsdf.gen": str(gen)}, chans).write(path)

    size = int(sys.argv[1])
    images = [image(0, size), image(1, size)]
    for line in sys.stdin:
        path, mode = line.split()
        pid = os.fork()
        if pid == 0:
            gen = 1
            while True:
                t0 = time.perf_counter()
                if mode == "atomic":
                    write_stokes_exr(path, images[gen % 2], metadata={"gen": gen})
                else:
                    direct_write(path, images[gen % 2], gen)
                if gen == 1:
                    print(f"ready {time.perf_counter() - t0:.4f}", flush=True)
                gen += 1
        print(f"pid {pid}", flush=True)
        os.waitpid(pid, 0)
        print("dead", flush=True)
""")


def _image(parity, size=SIZE):
    rng = np.random.default_rng(100 + parity)
    return {s: rng.random((size, size, 3), dtype=np.float32) for s in ("S0", "S1", "S2", "S3")}


def _intact(path, images):
    """True when ``path`` reads back and equals the image its 'gen' header names."""
    from hyde_bsdf.io.stokes_exr import read_stokes_exr

    try:
        st = read_stokes_exr(path)
        want = images[int(st["metadata"]["gen"]) % 2]
    except Exception:  # noqa: BLE001 -- any failure to read is a damaged file
        return False
    return all(np.array_equal(st[s], want[s]) for s in want)


def _kill_trials(tmp_path, mode, trials, rng):
    """Run ``trials`` SIGKILLs against the writer; return (intact flags, temporaries left)."""
    from hyde_bsdf.io.stokes_exr import write_stokes_exr

    images = [_image(0), _image(1)]
    proc = subprocess.Popen([sys.executable, "-c", ZYGOTE, str(SIZE)], cwd=ROOT, stdin=subprocess.PIPE,
                            stdout=subprocess.PIPE, text=True, bufsize=1)
    watchdog = threading.Timer(scaled(120), proc.kill)
    watchdog.start()
    intact, leftovers = [], 0
    try:
        for trial in range(trials):
            path = tmp_path / f"{mode}_{trial}.exr"
            write_stokes_exr(path, images[0], metadata={"gen": 0})   # the "old" file
            proc.stdin.write(f"{path} {mode}\n")
            proc.stdin.flush()
            pid = int(proc.stdout.readline().split()[1])
            seconds = float(proc.stdout.readline().split()[1])      # first write done: now looping
            threading.Event().wait(rng.uniform(0.0, 2.0 * seconds))
            os.kill(pid, signal.SIGKILL)
            assert proc.stdout.readline().strip() == "dead"
            intact.append(_intact(path, images))
            temps = list(tmp_path.glob(f".{path.name}.*"))
            leftovers += bool(temps)
            for t in temps:        # SIGKILL leaves the hidden temporary behind (nothing can remove it)
                t.unlink()
    finally:
        watchdog.cancel()
        proc.stdin.close()
        proc.wait(timeout=scaled(30))
    return intact, leftovers


def test_sigkill_during_exr_write_leaves_old_or_new_file(tmp_path):
    rng = random.Random(20261201)
    intact, leftovers = _kill_trials(tmp_path, "atomic", 24, rng)
    assert all(intact), f"{intact.count(False)} of {len(intact)} kills left a damaged EXR"
    # Most kills landed during a write (a temporary was left behind): the test exercised the window.
    assert leftovers >= 12, leftovers


def test_sigkill_control_non_atomic_write_is_damaged(tmp_path):
    """The same kills against a plain OpenEXR write do damage the file (so the check above can see it)."""
    rng = random.Random(7)
    intact, _ = _kill_trials(tmp_path, "direct", 5, rng)
    assert intact.count(False) >= 1, intact


def test_atomic_path_exception_keeps_old_file(tmp_path):
    target = tmp_path / "a.csv"
    target.write_text("old\n")
    with pytest.raises(KeyboardInterrupt):
        with atomic_open(target, "w") as f:
            f.write("new, half")
            raise KeyboardInterrupt
    assert target.read_text() == "old\n"
    assert [p.name for p in tmp_path.iterdir()] == ["a.csv"]      # no temporary left
    with atomic_path(target) as tmp:
        assert tmp.parent == tmp_path and tmp.name.endswith(".csv") and atomic.TEMP_NAME_RE.match(tmp.name)
        tmp.write_text("new\n")
        assert target.read_text() == "old\n"                       # not visible before the end
    assert target.read_text() == "new\n"


def test_atomic_file_permissions_follow_umask(tmp_path):
    old = os.umask(0o027)
    try:
        with atomic_open(tmp_path / "b.txt", "w") as f:
            f.write("x")
    finally:
        os.umask(old)
    assert (tmp_path / "b.txt").stat().st_mode & 0o777 == 0o640     # 0666 & ~027, not mkstemp's 0600


FSIZE_WRITER = textwrap.dedent(r"""
    import resource, signal, sys
    import numpy as np
    from hyde_bsdf.app.pictures import save_polarization_pngs
    from hyde_bsdf.io.stokes_exr import write_stokes_exr
    ramp = np.broadcast_to(np.linspace(0.1, 0.5, 32, dtype=np.float32)[:, None, None], (32, 32, 3))
    st = {"S0": ramp + 0.5, "S1": ramp, "S2": 0.5 * ramp, "S3": 0.0 * ramp}   # a ~3 KB EXR, ~10 KB PNGs
    out, limit = sys.argv[1], int(sys.argv[2])
    signal.signal(signal.SIGXFSZ, signal.SIG_IGN)       # writes past the limit fail with EFBIG
    resource.setrlimit(resource.RLIMIT_FSIZE, (limit, resource.RLIM_INFINITY))
    try:
        write_stokes_exr(out + ".exr", st)
        save_polarization_pngs(st, out)
    except OSError as exc:
        print(type(exc).__name__, exc.strerror)
""")


def _old_set(folder):
    folder.mkdir(exist_ok=True)
    names = ["a.exr"] + [f"a_{n}.png" for n in ("intensity", "dolp", "aolp", "docp", "rgb")]
    for n in names:
        (folder / n).write_bytes(b"old " + n.encode())
    return {n: (folder / n).read_bytes() for n in names}


@pytest.mark.parametrize("limit, failing", [(1000, "a.exr"), (6000, "a_intensity.png")])
def test_file_size_limit_keeps_the_file_it_stopped_at(tmp_path, limit, failing):
    """A real write failure from the real writers (the process's file-size limit: OpenEXR raises
    its RuntimeError, matplotlib an OSError): one OutputWriteError naming the file, that file and
    those after it byte for byte as they were, no temporary (the EXR, ~3 KB, is written first)."""
    before = _old_set(tmp_path)
    proc = subprocess.run([sys.executable, "-c", FSIZE_WRITER, str(tmp_path / "a"), str(limit)], cwd=ROOT,
                          capture_output=True, text=True, timeout=scaled(120))
    assert proc.returncode == 0, proc.stderr[-2000:]
    # OpenEXR's C++ stream may swallow the error of its last flush: the read-back check names it then
    reason = "(File too large|the file written does not read back complete .disk full or a file-size limit..)"
    assert re.fullmatch(f"OutputWriteError cannot write '{re.escape(str(tmp_path / failing))}': {reason}; "
                        r"the earlier file is unchanged", proc.stdout.strip()), proc.stdout
    after = {p.name: p.read_bytes() for p in tmp_path.iterdir()}
    assert set(after) == set(before)                                 # no temporary
    kept = [n for n in before if n != "a.exr"] if failing != "a.exr" else list(before)
    assert {n: after[n] for n in kept} == {n: before[n] for n in kept}


def test_temporary_names_fit_the_file_system(tmp_path):
    """A 244-character output name (the issue's render that failed at the end) gets a shortened
    temporary name of at most NAME_MAX bytes; a name that cannot fit is refused before any work."""
    name_max = os.pathconf(tmp_path, "PC_NAME_MAX")
    target = tmp_path / ("x" * 240 + ".exr")
    with atomic_path(target) as tmp:
        assert len(os.fsencode(tmp.name)) <= name_max and tmp.name.endswith(".exr")
        assert atomic.TEMP_NAME_RE.match(tmp.name)
        tmp.write_bytes(b"ok")
    assert target.read_bytes() == b"ok"
    check_output_path(tmp_path / ("x" * 240 + "_intensity.png"))        # 254 bytes: fits
    for bad in ("x" * 256 + ".exr", "é" * 128 + ".exr"):               # 260 and 260 bytes
        with pytest.raises(UsageError, match=f"the name is {len(os.fsencode(bad))} bytes, longer than the {name_max} "
                                             "bytes the file system allows"):
            check_output_path(tmp_path / bad, "--output")
    with pytest.raises(UsageError, match="longer than the .* bytes the file system allows; give a shorter path"):
        check_output_path("/" + "d/" * 2100 + "x.exr")
    assert sorted(p.name for p in tmp_path.iterdir()) == [target.name]


SIGTERM_WRITER = textwrap.dedent(r"""
    import sys, time
    from pathlib import Path
    from hyde_bsdf.app.signals import Terminated, handle_signals
    from hyde_bsdf.io.atomic import atomic_path
    out = Path(sys.argv[1])
    try:
        with handle_signals(), atomic_path(out / "a.exr") as tmp:
            tmp.write_bytes(b"half")
            print("ready", flush=True)
            time.sleep(60)
    except Terminated as exc:
        print("terminated", exc.signum, flush=True)
        sys.exit(143)
""")


def test_sigterm_removes_temporaries(tmp_path):
    (tmp_path / "a.exr").write_bytes(b"old")
    proc = subprocess.Popen([sys.executable, "-c", SIGTERM_WRITER, str(tmp_path)], cwd=ROOT,
                            stdout=subprocess.PIPE, text=True)
    try:
        assert proc.stdout.readline().strip() == "ready"
        assert len(list(tmp_path.iterdir())) == 2          # a.exr and its temporary
        proc.send_signal(signal.SIGTERM)
        out, _ = proc.communicate(timeout=scaled(30))
    finally:
        proc.kill()
    assert proc.returncode == 143 and out.strip() == "terminated 15"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.exr"]
    assert (tmp_path / "a.exr").read_bytes() == b"old"


def test_next_run_removes_what_a_killed_run_left(tmp_path):
    """Temporaries of a dead process (a child that has exited) are removed by the next run's
    output check; a live process's, and a user's look-alike file, stay."""
    dead = subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"], capture_output=True,
                          text=True).stdout.strip()
    host = atomic._HOST
    stale_file = tmp_path / f".a.exr.tmp-{host}-{dead}-abc123.exr"
    stale_dir = tmp_path / f".report.tmp-{host}-{dead}-abc123"
    live_file = tmp_path / f".b.exr.tmp-{host}-{os.getppid()}-abc123.exr"
    user_file = tmp_path / ".a.exr.notours.tmp.exr"
    for f in (stale_file, live_file, user_file):
        f.write_bytes(b"x")
    stale_dir.mkdir()
    (stale_dir / "index.html").write_text("half")
    check_output_path(tmp_path / "a.exr")                          # before the work of the next run
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted([live_file.name, user_file.name])


def test_check_output_paths_refuse_before_work(tmp_path):
    regular = tmp_path / "file.txt"
    regular.write_text("x")
    cases = [(check_output_path, tmp_path, "is a directory"),
             (check_output_path, regular / "out.exr", "not a directory"),
             (check_output_path, regular / "sub" / "out.exr", "cannot create the folder"),
             (check_output_path, "/proc/hyde_out.exr", "cannot write in '/proc'"),
             (check_output_dir, regular, "is a regular file"),
             (check_output_dir, regular / "sub", "cannot create the folder")]
    for func, path, needle in cases:
        with pytest.raises(UsageError, match=needle) as info:
            func(path, "--output")
        assert str(path) in str(info.value) and "\n" not in str(info.value)
    assert check_output_path(tmp_path / "new" / "x.exr") == tmp_path / "new" / "x.exr"
    assert (tmp_path / "new").is_dir()
