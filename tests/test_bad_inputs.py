"""The bad-input matrix (issue 10): every user mistake ends in one line that names the parameter or
file, exit status 2 on the command line, and no Python traceback; nothing is rendered or fitted
before the output paths and the scene have been checked.

``CLI_ROWS`` is one list of tuples ``(id, argv, exit_code, needle, how)``:

* ``argv``: the ``hyde-bsdf`` arguments; ``{name}`` is filled from the ``paths`` fixture below
  (``tmp``, ``file`` (a regular file), ``tiny`` (a small valid scene), ``nosensor``, ``ptracer``,
  ``inverse`` (scenes/inverse.xml), ``csv`` (a Mueller-measurement CSV), ``notreport``
  (a folder with a user's file in it));
* ``needle``: a piece of the last stderr line (it names the parameter or file);
* ``how``: ``"in"`` runs ``hyde_bsdf.cli.main`` in this process; ``"sub"`` runs
  ``python -m hyde_bsdf.cli`` (where a crash or signal is the point); ``"lowmem"`` is ``"in"``
  with ``MemAvailable`` read as 2 GiB; ``"nocheckout"`` is ``"in"`` with the validation scripts'
  folder missing; ``"sigint"`` sends Ctrl-C once the render's progress line appears;
  ``"pipe"`` closes the reader of stdout at once (``hyde-bsdf fit ... | head -0``);
  ``"cuda"`` is ``"in"``, run only on a machine without a CUDA GPU (hardware-dependent).

Append a row for each new mistake; ``API_ROWS`` does the same for Python calls
``(id, call(paths), exception type, needle)``.
"""
import os
import signal
import subprocess
import sys
import threading
from pathlib import Path

import pytest

from hyde_bsdf import cli
from hyde_bsdf.errors import UsageError

ROOT = Path(__file__).resolve().parent.parent

SCENE = """<scene version="3.0.0">
    <default name="spp" value="4"/>
    <default name="res" value="12"/>
    <integrator type="path"><integer name="max_depth" value="2"/></integrator>
    <sensor type="perspective">
        <transform name="to_world"><lookat origin="0, -4, 1" target="0, 0, 0.3" up="0, 0, 1"/></transform>
        <sampler type="independent"><integer name="sample_count" value="$spp"/></sampler>
        <film type="hdrfilm"><integer name="width" value="$res"/><integer name="height" value="8"/></film>
    </sensor>
    <shape type="sphere"><bsdf type="diffuse"/></shape>
    <emitter type="constant"/>
</scene>
"""

CLI_ROWS = [
    # --- render: output paths, checked before the render ---
    ("render: scene missing", ["render", "{tmp}/missing.xml", "-o", "{tmp}/a.exr"], 2, "scene file", "in"),
    ("render: output not .exr", ["render", "{tiny}", "-o", "{tmp}/a.png"], 2, "--output must end in .exr", "in"),
    ("render: output under a regular file", ["render", "{tiny}", "-o", "{file}/a.exr"], 2, "is not a directory", "in"),
    ("render: output in /proc", ["render", "{tiny}", "-o", "/proc/hyde.exr"], 2, "cannot write in '/proc'", "in"),
    ("render: output is a directory", ["render", "{tiny}", "-o", "{tmp}/dir.exr"], 2, "is a directory", "in"),
    ("render: a PNG path is a directory", ["render", "{tiny}", "-o", "{tmp}/pngdir.exr"], 2,
     "pngdir_dolp.png' is a directory", "in"),
    # --- render: scene sanity ---
    ("render: no sensor", ["render", "{nosensor}", "-o", "{tmp}/a.exr"], 2, "has no <sensor>", "in"),
    # Mitsuba re-raises the plugin's ValueError with its traceback inside the message: one line is left
    ("render: bad hyde parameter in the scene", ["render", "{badhyde}", "-o", "{tmp}/a.exr"], 2,
     "ValueError: hyde: rms_slope must be a finite number in the accepted range [0.0001, 50]", "in"),
    ("render: ptracer integrator", ["render", "{ptracer}", "-o", "{tmp}/a.exr"], 2, "integrator 'ptracer'", "in"),
    ("render: sample_count 0 (was SIGFPE)", ["render", "{inverse}", "-o", "{tmp}/a.exr", "-D", "spp=0"], 2,
     "sample_count is 0; it must be an integer >= 1 (the scene's $spp; set it with -D spp=N)", "sub"),
    ("render: film width 0", ["render", "{inverse}", "-o", "{tmp}/a.exr", "-D", "res=0"], 2,
     "film width is 0; it must be an integer >= 1", "in"),
    ("render: film beyond Dr.Jit's array limit", ["render", "{inverse}", "-o", "{tmp}/a.exr", "-D", "res=20000"],
     2, "film is too large", "in"),
    ("render: memory estimate above MemAvailable",
     ["render", "{inverse}", "-o", "{tmp}/a.exr", "-D", "res=5000", "--spp", "1"], 2,
     "GiB is available (MemAvailable); lower the film's width and height (the scene's $res; set it with -D res=N)",
     "lowmem"),
    ("render: spp beyond 2^16 passes", ["render", "{tiny}", "-o", "{tmp}/a.exr", "--spp", "100000000000"], 2,
     "lower --spp to <=", "in"),
    ("render: spp 0", ["render", "{tiny}", "-o", "{tmp}/a.exr", "--spp", "0"], 2, "--spp: expected an integer >= 1", "in"),
    ("render: seed out of range", ["render", "{tiny}", "-o", "{tmp}/a.exr", "--seed", "40000"], 2,
     "seed must be an integer in [0, 32767]", "in"),
    ("render: chunks above spp", ["render", "{tiny}", "-o", "{tmp}/a.exr", "--spp", "2", "--chunks", "5"], 2,
     "chunks must be an integer in [1, 2]", "in"),
    ("render: bad -D", ["render", "{tiny}", "-o", "{tmp}/a.exr", "-D", "noequals"], 2, "-D expects name=value", "in"),
    ("render: -D of an unknown name", ["render", "{tiny}", "-o", "{tmp}/a.exr", "-D", "nosuch=3"], 2,
     "unused parameters", "in"),
    ("render: unknown variant", ["render", "{tiny}", "-o", "{tmp}/a.exr", "--variant", "llvm_ad_rgbx"], 2,
     "variant must be one of", "in"),
    ("render: cuda variant without a GPU", ["render", "{tiny}", "-o", "{tmp}/a.exr", "--variant", "cuda_ad_rgb"], 2,
     "needs a CUDA GPU", "cuda"),
    ("render: Ctrl-C", ["render", "{tiny}", "-o", "{tmp}/sigint.exr", "--spp", "200000", "--chunks", "20000"], 130,
     "hyde-bsdf render: interrupted", "sigint"),
    # --- demo ---
    ("demo: outdir is a regular file", ["demo", "-o", "{file}"], 2, "is a regular file, not a folder", "in"),
    ("demo: outdir under a regular file", ["demo", "-o", "{file}/sub"], 2, "cannot create the folder", "in"),
    ("demo: outdir in /proc", ["demo", "-o", "/proc/hyde_demo"], 2, "'/proc/hyde_demo'", "in"),
    ("demo: scene missing", ["demo", "-o", "{tmp}/d", "--scene", "{tmp}/none.xml"], 2, "demo scene", "in"),
    ("demo: bad width", ["demo", "-o", "{tmp}/d", "--width", "0"], 2, "--width: expected an integer >= 1", "in"),
    # --- validate ---
    ("validate: outdir is a regular file", ["validate", "-o", "{file}"], 2, "is a regular file", "in"),
    ("validate: outdir under a regular file", ["validate", "-o", "{file}/r"], 2, "is a regular file", "in"),
    ("validate: outdir is a user's folder", ["validate", "-o", "{notreport}"], 2, "is not a validation report", "in"),
    ("validate: outdir is the current folder", ["validate", "-o", "."], 2, "is the current folder", "in"),
    ("validate: outside a source checkout", ["validate", "-o", "{tmp}/r"], 2, "source checkout", "nocheckout"),
    # --- fit (output path checked before the fit) ---
    ("fit: -o is a directory", ["fit", "{csv}", "-o", "{tmp}"], 2, "is a directory", "in"),
    ("fit: -o under a regular file", ["fit", "{csv}", "-o", "{file}/plot.png"], 2, "is not a directory", "in"),
    ("fit: stdout closed (| head)", ["fit", "{csv}"], 141, "", "pipe"),
    # --- invert (issue 15: a reference scaled by 1e30 ended in a drjit.backward traceback) ---
    ("invert: reference scaled by 1e30", ["invert", "--reference", "{ref1e30}", "--res", "16", "-o", "{tmp}/kept"], 2,
     "ref1e30.exr' has peak |S0| = 1e+30, outside the accepted range [1e-10, 1e+10]", "in"),
    # --- dispatcher ---
    ("unknown command", ["nosuch"], 2, "unknown command 'nosuch'", "in"),
]


def _api_rows():
    from hyde_bsdf.render.renderer import load_scene, plan_passes, prepare_variant, render_stokes
    from hyde_bsdf.render.stokes_io import write_stokes_exr

    def loaded(path):            # a scene loaded by Mitsuba itself, without our XML checks
        import mitsuba as mi

        prepare_variant("llvm_ad_spectral_polarized")
        return mi.load_file(str(path))

    return [
        ("render_stokes of a loaded scene without a sensor", lambda p: render_stokes(loaded(p["nosensor"])),
         UsageError, "the scene has no sensor"),
        ("render_stokes of a loaded ptracer scene", lambda p: render_stokes(loaded(p["ptracer"])), UsageError,
         r"integrator \(AdjointIntegrator\) is not a sampling integrator"),
        ("render_stokes spp=0", lambda p: render_stokes(p["tiny"], spp=0), UsageError, "spp must be an integer >= 1"),
        ("render_stokes seed=-1", lambda p: render_stokes(p["tiny"], seed=-1), UsageError,
         r"seed must be an integer in \[0, 32767\]"),
        ("render_stokes of a number", lambda p: render_stokes(3), UsageError, "scene_or_path must be"),
        ("load_scene without a sensor", lambda p: (prepare_variant("scalar_rgb"), load_scene(p["nosensor"])),
         UsageError, "has no <sensor>"),
        ("write_stokes_exr to .png", lambda p: write_stokes_exr(p["tmp"] / "x.png", {}), ValueError,
         r"must end in \.exr"),
        ("plan_passes beyond 2^16 passes", lambda p: plan_passes(1000, 1000, 10**7), UsageError,
         "at most 65536 passes"),
    ]


def _stokes_exr(path, size, value):
    """A Stokes EXR (R, G, B, S0.R ... S3.B) of size x size pixels: S0 = value, S1 = value / 2, S2 = S3 = 0."""
    import numpy as np
    import OpenEXR

    names = ["R", "G", "B"] + [f"S{i}.{c}" for i in range(4) for c in "RGB"]
    level = {"R": 1.0, "G": 1.0, "B": 1.0, "S0": 1.0, "S1": 0.5, "S2": 0.0, "S3": 0.0}
    ch = {n: np.full((size, size), value * level[n.split(".")[0]], np.float32) for n in names}
    OpenEXR.File({"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}, ch).write(str(path))


@pytest.fixture(scope="module")
def paths(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("bad")
    (tmp / "file.txt").write_text("a regular file\n")
    (tmp / "tiny.xml").write_text(SCENE)
    (tmp / "nosensor.xml").write_text('<scene version="3.0.0"><shape type="sphere"/><emitter type="constant"/>'
                                      "</scene>")
    (tmp / "ptracer.xml").write_text(SCENE.replace('<integrator type="path">', '<integrator type="ptracer">'))
    (tmp / "badhyde.xml").write_text(SCENE.replace('<bsdf type="diffuse"/>', '<bsdf type="hyde"><float name="rms_slope" value="-1"/></bsdf>'))
    _stokes_exr(tmp / "ref1e30.exr", 16, 1e30)
    (tmp / "kept").mkdir()
    (tmp / "kept" / "invert_history.csv").write_text("a previous run's output\n")
    (tmp / "dir.exr").mkdir()
    (tmp / "pngdir_dolp.png").mkdir()
    (tmp / "notreport").mkdir()
    (tmp / "notreport" / "thesis.tex").write_text("a user's file")
    import numpy as np

    from hyde_bsdf.fit.measurements import write_measurements
    from hyde_bsdf.fit.mueller_fit import synthetic_measurements

    th = np.radians([20.0, 40.0, 60.0])
    meas = synthetic_measurements(th, th, np.full(3, np.pi), n=1.5, k=3.0, rms_slope=0.3)
    write_measurements(tmp / "meas.csv", meas)
    return {"tmp": tmp, "file": tmp / "file.txt", "tiny": tmp / "tiny.xml", "nosensor": tmp / "nosensor.xml",
            "ptracer": tmp / "ptracer.xml", "inverse": ROOT / "scenes" / "inverse.xml", "csv": tmp / "meas.csv",
            "notreport": tmp / "notreport", "badhyde": tmp / "badhyde.xml", "ref1e30": tmp / "ref1e30.exr"}


def _fill(argv, paths):
    return [a.format(**{k: str(v) for k, v in paths.items()}) for a in argv]


def _subprocess(argv, how, timeout=120):
    cmd = [sys.executable, "-m", "hyde_bsdf.cli", *argv]
    if how == "pipe":
        proc = subprocess.Popen(cmd, cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        proc.stdout.close()                       # the reader went away before any output
        err = proc.stderr.read()
        return proc.wait(timeout=timeout), "", err
    if how == "sigint":
        proc = subprocess.Popen(cmd, cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        watchdog = threading.Timer(timeout, proc.kill)
        watchdog.start()
        err = ""
        try:
            while "spp (" not in err:             # the first progress line: rendering has begun
                ch = proc.stderr.read(1)
                if not ch:
                    break
                err += ch
            proc.send_signal(signal.SIGINT)
            out, rest = proc.communicate(timeout=timeout)
        finally:
            watchdog.cancel()
        return proc.returncode, out, err + rest
    proc = subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True, timeout=timeout)
    return proc.returncode, proc.stdout, proc.stderr


@pytest.mark.parametrize("row", CLI_ROWS, ids=[r[0] for r in CLI_ROWS])
def test_cli_bad_input(row, paths, capsys, monkeypatch):
    name, argv, code, needle, how = row
    argv = _fill(argv, paths)
    if how == "cuda":
        import drjit as dr

        if dr.has_backend(dr.JitBackend.CUDA):
            pytest.skip("hardware-dependent: this machine has a CUDA GPU, so the variant works")
    if how in ("sub", "sigint", "pipe"):
        got, out, err = _subprocess(argv, how)
    else:
        if how == "lowmem":
            monkeypatch.setattr("hyde_bsdf.render.renderer.mem_available", lambda: 2 * 2**30)
        if how == "nocheckout":
            monkeypatch.setattr("hyde_bsdf.report.build.VALIDATION_DIR", paths["tmp"] / "no_validation")
        monkeypatch.chdir(paths["tmp"])
        try:
            got = cli.main(argv)
        except SystemExit as exc:                 # argparse errors of commands that do not catch them
            got = exc.code
        out, err = capsys.readouterr()
    assert got == code, (got, err[-2000:])
    assert "Traceback" not in err and "Traceback" not in out, err[-3000:]
    lines = [ln for ln in err.replace("\r", "\n").splitlines() if ln.strip()]
    if how == "pipe":
        assert not lines, err                     # quiet
        return
    assert lines, "no message on stderr"
    assert lines[-1].startswith(f"hyde-bsdf {argv[0]}"), lines[-1]
    assert needle in lines[-1], lines[-1]
    assert (paths["tmp"] / "kept" / "invert_history.csv").read_text() == "a previous run's output\n"   # no file lost
    if how == "sigint":
        assert not (paths["tmp"] / "sigint.exr").exists()
        assert not list(paths["tmp"].glob(".sigint.exr.*"))   # no temporary left behind


def test_api_bad_input(paths):
    for name, call, exc_type, needle in _api_rows():
        with pytest.raises(exc_type, match=needle) as info:
            call(paths)
        assert "\n" not in str(info.value), name


def test_huge_spp_is_split_into_passes_below_mitsuba_limit():
    """--spp 10^9 on a 12 x 8 film (which segfaulted in one Mitsuba call) becomes passes of at
    most 2^26 samples (Mitsuba's own per-pass limit is 2^32), with every sample kept."""
    from hyde_bsdf.render.renderer import MAX_SAMPLES_PER_PASS, plan_passes

    sizes = plan_passes(12, 8, 10**9)
    assert sum(sizes) == 10**9
    assert max(sizes) * 96 <= MAX_SAMPLES_PER_PASS < 2**32
    assert len(sizes) == 1431 and max(sizes) - min(sizes) <= 1
    assert plan_passes(12, 8, 16) == [2] * 8                # small renders: the default 8 chunks
    assert plan_passes(12, 8, 16, chunks=3) == [6, 5, 5]
