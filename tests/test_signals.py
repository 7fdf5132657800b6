"""A signal at any moment (issue 33, item 2): the sweep.

Each long command -- ``render``, ``fit``, ``invert --maps`` (whole picture, and ``--tiles`` on a
pool of 2 worker processes), ``stokes``, ``export`` -- runs once to its end (exit 0; its duration T),
then 8 times more, each run receiving a signal at t = k T / 8, k = 0..7: from the interpreter's
start (k = 0) through the imports of NumPy, Dr.Jit and Mitsuba, scene loading, worker start-up,
JIT compilation and the work, to the writing of the outputs.  The signal goes round SIGTERM,
SIGINT (to the run's whole process group, as a terminal's Ctrl-C), SIGHUP.  Every output file exists beforehand with old contents.

Timing decides no assertion: whatever moment the signal lands, the run ends in one of the
outcomes hyde_bsdf.app.signals documents, and each is checked in full:

* it had ended before the signal (exit 0);
* interrupted: exit 128 + the signal (130 / 143 / 129), one ``hyde-bsdf CMD: interrupted`` or
  ``... terminated (SIGTERM)`` line last on stderr, no traceback, no other error line;
* the signal came before the first line of ``hyde-bsdf`` ran (the interpreter's start): the
  process ended by the signal, nothing on stderr, every output old;

and in every case: each output is its old file or a complete new one (it loads), no temporary is
left, nothing else appears in the folder, and no process of the run is left alive (each run is the
leader of its own session; its session is empty at the end).  A run still alive when the signal is
sent never ends with 0.

The moments follow the last run that ended by itself (a later run is faster: Dr.Jit's kernel cache is
warm).  Cost: about 6 x 9 short runs; ~60 s of two workers' time on a quiet 2-core machine.
"""
import json
import os
import re
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from conftest import scaled

from hyde_bsdf.io.atomic import TEMP_NAME_RE

ROOT = Path(__file__).resolve().parent.parent
SIGNALS = (signal.SIGTERM, signal.SIGINT, signal.SIGHUP)
MOMENTS = 8

SCENE = """<scene version="3.0.0">
    <integrator type="path"><integer name="max_depth" value="2"/></integrator>
    <sensor type="perspective">
        <transform name="to_world"><lookat origin="0, -4, 1" target="0, 0, 0.3" up="0, 0, 1"/></transform>
        <sampler type="independent"><integer name="sample_count" value="4"/></sampler>
        <film type="hdrfilm"><integer name="width" value="12"/><integer name="height" value="8"/></film>
    </sensor>
    <shape type="sphere"><bsdf type="hyde"><float name="rms_slope" value="0.3"/></bsdf></shape>
    <emitter type="constant"/>
</scene>
"""
SAMPLE = """<scene version="3.0.0">
  <integrator type="stokes"><integrator type="path"><integer name="max_depth" value="2"/></integrator></integrator>
  <shape type="rectangle"><bsdf type="hyde"><texture type="bitmap" name="alpha"><string name="filename"
    value="alpha0.exr"/><boolean name="raw" value="true"/><string name="filter_type" value="nearest"/></texture>
    <float name="eta" value="1.5"/></bsdf></shape>
</scene>"""


def _inputs(d: Path) -> None:
    """The input files of every command, in ``d``."""
    import mitsuba as mi
    import OpenEXR

    from hyde_bsdf.fit.mueller_fit import synthetic_measurements
    from hyde_bsdf.io.measurements import write_measurements

    (d / "scene.xml").write_text(SCENE)
    th = np.radians([20.0, 35.0, 50.0, 65.0])         # more geometries than the 3 parameters: a fit, not a warning
    write_measurements(d / "meas.csv", synthetic_measurements(th, th, np.full(4, np.pi), n=1.5, k=3.0, rms_slope=0.3, rng=4))
    np.save(d / "mosaic.npy", np.random.default_rng(0).uniform(200, 800, (32, 32)))
    mi.set_variant("scalar_rgb")
    mi.Bitmap(np.full((4, 4, 1), 0.3, np.float32)).write(str(d / "alpha0.exr"))
    (d / "sample.xml").write_text(SAMPLE)
    eye = np.array([2.2, 0.0, 2.2])
    z = -eye / np.linalg.norm(eye)
    x = np.cross(z, [0.0, 0.0, 1.0]) / np.linalg.norm(np.cross(z, [0.0, 0.0, 1.0]))
    R = np.stack([x, np.cross(z, x), z])
    (d / "camera.json").write_text(json.dumps({"width": 24, "height": 24, "fx": 30.0, "fy": 30.0, "cx": 11.5,
                                               "cy": 11.5, "R": R.tolist(), "t": (-R @ eye).tolist()}))
    (d / "lights.json").write_text(json.dumps({"lights": [{"type": "point", "position": [-2.5, 0.4, 2.5],
                                                           "intensity": 20}]}))
    ch = {s: np.full((24, 24), v, np.float32) for s, v in (("S0", 0.05), ("S1", 0.01), ("S2", 0.005))}
    OpenEXR.File({"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}, ch).write(str(d / "ref.exr"))


QUICK_MAPS = ["--iterations", "2", "--spp", "1", "--no-uncertainty", "-o", "out"]
#: command -> (argv, the outputs in out/)
RUNS = {
    "render": (["render", "scene.xml", "-o", "out/r.exr"],
               ["r.exr", "r_intensity.png", "r_dolp.png", "r_aolp.png", "r_docp.png", "r_rgb.png"]),
    "fit": (["fit", "meas.csv", "--model", "fixed", "-o", "out/fit.png"], ["fit.png"]),
    "stokes": (["stokes", "--mosaic", "mosaic.npy", "-o", "out/s.exr"],
               ["s.exr", "s_intensity.png", "s_dolp.png", "s_aolp.png"]),
    "export": (["export", "out/t.pbsdf", "--rms-slope", "0.3", "--n", "1.5", "--resolution", "4x4x4",
                "--error-samples", "200"], ["t.pbsdf"]),
    "invert --maps": (["invert", "--maps", "--map-size", "4", "--res", "16", "--spp-ref", "4"] + QUICK_MAPS,
                      ["invert_maps_history.csv", "invert_maps.png", "alpha.npy", "alpha.exr", "alpha_seen.npy",
                       "alpha_seen.exr"]),
    "invert --maps --tiles": (["invert", "--maps", "--scene", "sample.xml", "--camera", "camera.json", "--light",
                               "lights.json", "--reference", "ref.exr", "--tiles", "2", "--workers", "2"] + QUICK_MAPS,
                              ["invert_maps_history.csv", "invert_maps.png", "alpha.npy", "alpha.exr",
                               "alpha_seen.npy", "alpha_seen.exr"]),
}


def _complete(path: Path) -> bool:
    """Whether ``path`` holds a whole file of its kind (it loads)."""
    try:
        if path.suffix == ".exr":
            import OpenEXR
            return bool(OpenEXR.File(str(path)).channels())
        if path.suffix == ".png":
            from PIL import Image
            with Image.open(path) as im:
                im.load()
            return True
        if path.suffix == ".npy":
            return np.load(path).size > 0
        if path.suffix == ".pbsdf":
            from hyde_bsdf.io.pbsdf_file import read_pbsdf
            return read_pbsdf(path) is not None
        return path.read_text().endswith("\n") and len(path.read_text().splitlines()) >= 2   # a CSV
    except Exception:  # noqa: BLE001 -- a file that does not load is not complete
        return False


def _session(sid: int) -> list[int]:
    """Live (not zombie) processes of session ``sid``."""
    alive = []
    for entry in os.listdir("/proc"):
        try:
            with open(f"/proc/{entry}/stat", "rb") as fh:
                fields = fh.read().rsplit(b")", 1)[1].split()
        except (OSError, ValueError):
            continue
        if entry.isdigit() and int(fields[3]) == sid and fields[0] != b"Z":
            alive.append(int(entry))
    return alive


def _run(d: Path, argv, outputs, delay=None, sig=signal.SIGTERM):
    """Run ``hyde-bsdf ARGV`` in ``d`` (old outputs in d/out), signalled after ``delay`` s; returns
    (exit status, stderr, whether it was still running when signalled, seconds)."""
    (d / "out").mkdir(exist_ok=True)
    for name in outputs:
        (d / "out" / name).write_bytes(b"old " + name.encode())
    t0 = time.monotonic()
    proc = subprocess.Popen([sys.executable, "-m", "hyde_bsdf.app.cli", *argv], cwd=d, stdout=subprocess.DEVNULL,
                            stderr=subprocess.PIPE, start_new_session=True,
                            env={**os.environ, "PYTHONPATH": str(ROOT)})
    running, _run.pid = None, proc.pid
    if delay is not None:
        try:
            proc.wait(timeout=delay)
        except subprocess.TimeoutExpired:
            running = True         # Ctrl-C reaches the terminal's whole process group; kill, the process
            os.killpg(proc.pid, sig) if sig == signal.SIGINT else proc.send_signal(sig)
    try:
        err = proc.communicate(timeout=scaled(300))[1].decode(errors="replace")
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
    return proc.returncode, err, running, time.monotonic() - t0


def _check(d: Path, command: str, outputs, code, err, running, sig):
    name = command.split()[0]
    lines = [ln for ln in err.splitlines() if ln.strip()]
    old = {n: (d / "out" / n).read_bytes() == b"old " + n.encode() for n in outputs}
    if code == 0:
        assert not running, f"{command}: signalled while running, and ended with 0: {err[-2000:]}"
    elif code == -sig:                     # before the first line of hyde-bsdf: the default action
        assert not lines and all(old.values()), (command, err[-2000:])
    else:
        message = "interrupted" if sig == signal.SIGINT else f"terminated ({signal.Signals(sig).name})"
        assert code == 128 + sig, (command, code, err[-3000:])
        assert lines[-1] == f"hyde-bsdf {name}: {message}", (command, lines[-3:])
        assert "Traceback" not in err and not any(re.match(rf"hyde-bsdf {name}: (error|warning)", ln)
                                                 for ln in lines), (command, err[-3000:])
    for n in outputs:
        assert old[n] or _complete(d / "out" / n), f"{command}: out/{n} is neither the old file nor a whole new one"
    assert sorted(p.name for p in (d / "out").iterdir()) == sorted(outputs), f"{command}: temporaries or strays left"
    assert not [p for p in d.rglob("*") if TEMP_NAME_RE.match(p.name)]


def _wait_session_empty(sid: int):
    deadline = time.monotonic() + scaled(20)
    while _session(sid) and time.monotonic() < deadline:      # SIGKILL is delivered asynchronously
        time.sleep(0.1)
    assert not _session(sid), f"processes of the run left alive: {_session(sid)}"


@pytest.fixture(scope="module")
def inputs(tmp_path_factory):
    d = tmp_path_factory.mktemp("signals_inputs")
    _inputs(d)
    return d


@pytest.mark.parametrize("command", list(RUNS))
def test_a_signal_at_any_moment_ends_the_run_with_one_line(command, inputs, tmp_path):
    argv, outputs = RUNS[command]

    def fresh(k):
        d = tmp_path / f"run{k}"
        d.mkdir()
        for p in inputs.iterdir():
            os.symlink(p, d / p.name)
        return d

    d = fresh("ref")
    code, err, _, seconds = _run(d, argv, outputs)
    assert code == 0 and not any(ln.startswith(f"hyde-bsdf {command.split()[0]}:") for ln in err.splitlines()), \
        err[-3000:]
    assert all(_complete(d / "out" / n) for n in outputs)
    for k in range(MOMENTS):
        sig, d = SIGNALS[k % 3], fresh(k)
        code, err, running, took = _run(d, argv, outputs, delay=k * seconds / MOMENTS, sig=sig)
        _check(d, command, outputs, code, err, running, sig)
        _wait_session_empty(_run.pid)
        if code == 0:
            seconds = took         # the run was faster than the one that set the moments (warm caches)
