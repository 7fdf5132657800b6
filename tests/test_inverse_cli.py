"""``hyde-bsdf invert`` on bad input and interruption (through ``hyde_bsdf.app.cli.main``), and its
texture-valued mode end to end.

Behaviour checked: every user mistake is one line on stderr naming the parameter or file, exit 2,
no traceback, and is found before any rendering (a bad output folder is refused before the
optimisation, not after it); a memory estimate above the free memory is refused with the flag that
lowers it; progress is one stderr line per iteration; Ctrl-C (SIGINT) ends with a short message
and exit 130; outputs appear complete (atomic, no temporary files left).
"""
import signal
import subprocess
import threading
import sys
from pathlib import Path

import numpy as np
import pytest
from conftest import scaled

from hyde_bsdf.app.cli import main
from hyde_bsdf import inverse as inv

TINY = ["--res", "16", "--spp", "4", "--spp-ref", "16"]


def _exr(path, h, w, nan=False):
    """A Stokes EXR (channels R, G, B, S0.R ... S3.B) of h x w pixels, optionally with one NaN."""
    import OpenEXR

    rng = np.random.default_rng(0)
    names = ["R", "G", "B"] + [f"S{i}.{c}" for i in range(4) for c in "RGB"]
    ch = {n: rng.uniform(0.1, 1.0, (h, w)).astype(np.float32) for n in names}
    if nan:
        ch["S1.G"][h // 2, w // 3] = np.nan
    OpenEXR.File({"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}, ch).write(str(path))
    return str(path)


def _run(capsys, argv):
    rc = main(["invert"] + argv)
    cap = capsys.readouterr()
    assert "Traceback" not in cap.err and "Traceback" not in cap.out
    return rc, cap.out, cap.err


def _one_error_line(err):
    lines = [line for line in err.splitlines() if line.startswith("hyde-bsdf invert")]
    assert len(lines) == 1, err
    return lines[0]


@pytest.mark.parametrize("argv, words", [
    (["--seed", "-5"], ["--seed", ">= 0", "-5"]),
    (["--seed", "x"], ["--seed", "invalid int"]),
    (["--iterations", "0"], ["--iterations", ">= 1"]),
    (["--lr", "nan"], ["--lr", "> 0"]),
    (["--start", "rms_slope=abc"], ["--start", "not a number"]),
    (["--start", "rms_slope=60"], ["--start", "outside the accepted range"]),
    (["--fit", "sigma"], ["--fit", "rms_slope, eta, k"]),
    (["--regularizer", "tv"], ["--regularizer", "--maps"]),
    (["--maps", "--regularizer", "tikhonov"], ["--regularizer", "invalid choice"]),
    (["--maps", "--weight", "-1"], ["--weight", ">= 0"]),
    (["--maps", "--fit", "alpha,rms_slope"], ["--fit", "same roughness"]),
    (["--reference", "/nonexistent/ref.exr"], ["/nonexistent/ref.exr", "does not exist"]),
    (["--maps", "--scene", "hyde_bsdf/data/scenes/inverse.xml"], ["--reference per scene"]),
])
def test_usage_errors_are_one_line_exit_2(capsys, argv, words):
    rc, _, err = _run(capsys, argv)
    assert rc == 2
    line = _one_error_line(err)
    for w in words:
        assert w in line, (w, line)


def test_reference_of_wrong_size_and_with_nan(capsys, tmp_path):
    rc, _, err = _run(capsys, TINY + ["--reference", _exr(tmp_path / "small.exr", 10, 12), "-o", str(tmp_path)])
    assert rc == 2
    line = _one_error_line(err)
    assert "--reference" in line and "small.exr" in line and "12x10 pixels" in line and "16x16" in line
    rc, _, err = _run(capsys, TINY + ["--reference", _exr(tmp_path / "nan.exr", 16, 16, nan=True),
                                      "-o", str(tmp_path)])
    assert rc == 2
    line = _one_error_line(err)
    assert "--reference" in line and "nan.exr" in line and "1 pixel(s) with NaN" in line
    assert "[invert] it" not in err                # refused before any optimisation step
    assert not list(tmp_path.glob("invert*"))


def test_bad_output_path_refused_before_optimising(capsys, tmp_path):
    blocker = tmp_path / "file.txt"
    blocker.write_text("x")
    for out in (blocker / "sub", blocker):
        rc, _, err = _run(capsys, TINY + ["--iterations", "50", "-o", str(out)])
        assert rc == 2
        line = _one_error_line(err)
        assert "-o/--output" in line and "file.txt" in line
        assert "[invert]" not in err               # nothing rendered


def test_memory_estimate_refused_with_the_flag(capsys, monkeypatch, tmp_path):
    monkeypatch.setattr("hyde_bsdf.resources.available_memory", lambda: 64 * 2**20)
    rc, _, err = _run(capsys, TINY + ["-o", str(tmp_path)])
    assert rc == 2
    line = _one_error_line(err)
    assert "of memory needed" in line and "64 MiB is available" in line and "--spp" in line and "--res" in line
    rc, _, err = _run(capsys, ["--maps"] + TINY + ["-o", str(tmp_path)])
    assert rc == 2 and "--spp" in _one_error_line(err)
    from hyde_bsdf.resources import COSTS, inversion_bytes
    assert inversion_bytes(64 * 64, 16) == COSTS.ad_fixed_bytes + COSTS.ad_bytes_per_sample * 64 * 64 * 16


def test_maps_mode_end_to_end_progress_and_atomic_outputs(capsys, tmp_path):
    rc, out, err = _run(capsys, ["--maps", "--map-size", "8", "--iterations", "3", "--regularizer", "tv",
                                 "--weight", "0.1"] + TINY + ["-o", str(tmp_path)])
    assert rc == 0
    # one progress line per iteration on stderr
    assert [line.split()[2] for line in err.splitlines() if line.startswith("[invert] it")] == ["1/3", "2/3", "3/3"]
    alpha = np.load(tmp_path / "alpha.npy")
    assert alpha.shape == (8, 8) and np.isfinite(alpha).all()
    assert "per-texel error over the" in out and "texels seen by the images" in out
    rows = (tmp_path / "invert_maps_history.csv").read_text().splitlines()
    assert rows[0].startswith("iteration,loss,data_loss,regularizer") and len(rows) == 1 + 3
    assert (tmp_path / "invert_maps.png").stat().st_size > 5_000 and (tmp_path / "alpha.exr").stat().st_size > 0
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".")]     # no temporary files left
    se = np.load(tmp_path / "alpha_stderr.npy")                               # the standard-error map
    assert se.shape == (8, 8) and np.all(se[np.isfinite(se)] > 0)


def test_maps_preset_dielectric_end_to_end(capsys, tmp_path):
    """--preset dielectric: the designed acquisition (7 pictures) of the built-in sample on a 2 x 2 map,
    eta and alpha fitted, standard-error maps written and their medians printed."""
    rc, out, err = _run(capsys, ["--maps", "--preset", "dielectric", "--map-size", "2", "--res", "8", "--spp-ref", "16",
                                 "--iterations", "3", "-o", str(tmp_path)])
    assert rc == 0, err
    assert "preset: 7 pictures of 8x8 px (0 behind a polarizer)" in err
    for n in ("alpha", "eta"):
        assert np.load(tmp_path / f"{n}.npy").shape == (2, 2) and (tmp_path / f"{n}_stderr.exr").stat().st_size > 0
    assert out.count("relative standard error: median") == 2
    rc, _, err = _run(capsys, ["--maps", "--preset", "dielectric", "--fit", "alpha,k", "-o", str(tmp_path / "x")])
    assert rc == 2 and "--fit: the dielectric preset fits alpha, eta and specular_reflectance" in err


def test_ctrl_c_exits_130_with_a_short_message(tmp_path):
    code = ("import sys; from hyde_bsdf.app.cli import main; "
            f"sys.exit(main(['invert', '--res', '16', '--spp', '4', '--spp-ref', '16', '--iterations', '100000', "
            f"'-o', {str(tmp_path)!r}]))")
    proc = subprocess.Popen([sys.executable, "-c", code], stderr=subprocess.PIPE, stdout=subprocess.PIPE,
                            text=True, cwd=Path(__file__).resolve().parents[1])
    lines = []
    watchdog = threading.Timer(scaled(300), proc.kill)   # a hang guard only: the waits are events
    watchdog.start()
    try:
        for line in proc.stderr:                   # wait until the optimisation runs: its first
            lines.append(line)                     # iteration line (after the reference and the JIT)
            if line.startswith("[invert] it"):
                break
        proc.send_signal(signal.SIGINT)
        _, rest = proc.communicate()
    finally:
        watchdog.cancel()
        if proc.poll() is None:
            proc.kill()
    err = "".join(lines) + rest
    assert proc.returncode == 130, err
    assert "hyde-bsdf invert: interrupted" in err and "Traceback" not in err
    assert not (tmp_path / "invert_history.csv").exists()


def test_maps_user_scene_bilinear_unseen_and_warnings_once(capfd, tmp_path):
    """Two --scene files whose alpha bitmap (4 x 4) has no filter_type (bilinear) and whose camera sees
    only part of the plane: the bitmaps are fitted with nearest lookup and one WARNING says so;
    alpha_seen.npy/.exr mark the texels seen; unseen texels are NaN in alpha.npy (no start value
    posing as a result); every WARNING line appears once; Mitsuba's 'Monochrome mode enabled' (an rgb
    film in the mono variant) at most once for the run; the printed range counts the valid texels."""
    import re

    import mitsuba as mi

    mi.Bitmap(np.full((4, 4, 1), 0.3, np.float32)).write(str(tmp_path / "alpha_start.exr"))
    xml = """<scene version="3.0.0">
    <integrator type="stokes"><integrator type="path"><integer name="max_depth" value="2"/></integrator></integrator>
    <sensor type="perspective"><float name="fov" value="14"/>
        <transform name="to_world"><lookat origin="0.4, -0.3, 4" target="0.4, -0.3, 0" up="0, 1, 0"/></transform>
        <film type="hdrfilm"><integer name="width" value="16"/><integer name="height" value="16"/><rfilter type="box"/></film>
        <sampler type="independent"><integer name="sample_count" value="4"/></sampler></sensor>
    <shape type="rectangle" id="plane"><bsdf type="hyde">
        <texture name="alpha" type="bitmap"><string name="filename" value="alpha_start.exr"/>
            <boolean name="raw" value="true"/></texture>
        <float name="eta" value="1.5"/><float name="k" value="3"/></bsdf></shape>
    <emitter type="directional"><vector name="direction" value="0.3, 0, -1"/><rgb name="irradiance" value="2"/></emitter>
    </scene>"""
    argv = ["invert", "--maps", "--iterations", "2", "--spp", "4", "-o", str(tmp_path / "out")]
    for i in range(2):
        (tmp_path / f"s{i}.xml").write_text(xml)
        argv += ["--scene", str(tmp_path / f"s{i}.xml"), "--reference", _exr(tmp_path / f"r{i}.exr", 16, 16)]
    capfd.readouterr()
    rc = main(argv)
    cap = capfd.readouterr()
    assert rc == 0, cap.err
    out = re.sub(r"\x1b\[[0-9;]*m", "", cap.out)          # Mitsuba's log colours (it logs to stdout)
    warned = [line for line in out.splitlines() if line.startswith("WARNING:")]
    assert len(warned) == len(set(warned)) and sum("filter bilinearly" in w for w in warned) == 1, cap.out
    assert (cap.out + cap.err).count("Monochrome mode enabled") <= 1
    seen = np.load(tmp_path / "out" / "alpha_seen.npy")
    alpha = np.load(tmp_path / "out" / "alpha.npy")
    assert seen.shape == (4, 4) and 0 < seen.sum() < 16 and (tmp_path / "out" / "alpha_seen.exr").stat().st_size > 0
    assert np.all(np.isnan(alpha[seen == 0])) and np.all(np.isfinite(alpha[seen == 1]))
    assert "texels with a valid standard error" in cap.out
