"""``hyde-bsdf stokes`` and the camera options of ``hyde-bsdf invert --maps``: outputs written, and bad
input answered with one line and exit 2 (no traceback, nothing written)."""
import json

import numpy as np
import pytest
from conftest import textured_plane_scene

from hyde_bsdf.app.cli import main
from hyde_bsdf.model.polarimetry import CameraNoise, simulate_mosaic
from hyde_bsdf.io.stokes_exr import read_camera_stokes


@pytest.fixture
def raw(tmp_path):
    rng = np.random.default_rng(0)
    S = np.zeros((4, 6, 8))
    S[0], S[1], S[2] = 2000.0, 400.0, -300.0
    path = tmp_path / "raw.npy"
    np.save(path, np.round(simulate_mosaic(S, CameraNoise(read_noise=3.0, black_level=64.0), rng)).astype(np.uint16))
    return path


def test_stokes_writes_the_exr_and_the_charts(raw, tmp_path, capsys):
    """A DoFP mosaic: S0, S1, S2 at the super-pixel grid, with sigma and mask, in radiance units after
    --dn-per-unit; DoLP 0.25 recovered within 5 sigma-ish noise (sigma/S0 ~ 1.6 %)."""
    out = tmp_path / "s.exr"
    assert main(["stokes", "--mosaic", str(raw), "--read-noise", "3", "--black-level", "64", "--dn-per-unit", "1000",
                 "-o", str(out)]) == 0
    d = read_camera_stokes(out)
    assert sorted(d["stokes"]) == ["S0", "S1", "S2"] and sorted(d["sigma"]) == ["S0", "S1", "S2"] and d["mask"].all()
    assert d["stokes"]["S0"].shape == (6, 8, 1)
    assert np.median(d["stokes"]["S0"]) == pytest.approx(2.0, rel=0.02)
    dolp = np.hypot(d["stokes"]["S1"], d["stokes"]["S2"]) / d["stokes"]["S0"]
    assert np.median(dolp) == pytest.approx(0.25, abs=0.02)
    for name in ("intensity", "dolp", "aolp"):
        assert (tmp_path / f"s_{name}.png").is_file()
    assert "S0+S1+S2 at 8x6 px" in capsys.readouterr().out


@pytest.mark.parametrize("args, message", [
    (["--frames", "RAW", "RAW", "--angles", "0,90"], "need at least 3 analyzer frames"),
    (["--frames", "RAW", "RAW", "RAW"], "--frames needs --angles"),
    (["--mosaic", "RAW", "--layout", "0,45,90"], "--layout needs 4 angles"),
    (["--mosaic", "RAW", "--full-well", "100"], "at or above the saturation level"),
    (["--mosaic", "missing.npy"], "does not exist"),      # the input gate's words (issue 33: read_array)
])
def test_stokes_bad_input_is_one_line(args, message, raw, tmp_path, capsys):
    argv = ["stokes"] + [str(raw) if a == "RAW" else a for a in args] + ["-o", str(tmp_path / "x.exr")]
    assert main(argv) == 2
    err = capsys.readouterr().err.strip()
    assert message in err and len(err.splitlines()) == 1
    assert not (tmp_path / "x.exr").exists()


def test_stokes_without_room_is_refused_before_writing(raw, tmp_path, capsys, monkeypatch):
    """A disk with 50 KB free: the EXR (S0..S2, their sigma and the mask: 7 float32 channels of 8x6)
    and the three charts (704 x 515 px each, bounded as uncompressed RGBA) need about 4.41 MiB; one
    line naming -o and both sizes, exit 2, and the earlier EXR is left as it was."""
    import shutil

    out = tmp_path / "x.exr"
    out.write_bytes(b"an earlier run's EXR")
    usage = shutil.disk_usage(tmp_path)
    monkeypatch.setattr(shutil, "disk_usage", lambda path: usage._replace(free=50_000))
    assert main(["stokes", "--mosaic", str(raw), "-o", str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1
    assert "-o/--output" in err and "x.exr' (8x6 px): about 4.41 MiB needed, but" in err and "48.8 KiB free" in err
    assert out.read_bytes() == b"an earlier run's EXR" and not (tmp_path / "x_intensity.png").exists()


def test_invert_camera_options_are_checked_first(tmp_path, capsys):
    (tmp_path / "cam.json").write_text(json.dumps({"width": 4, "height": 4}))
    assert main(["invert", "--maps", "--camera", str(tmp_path / "cam.json"), "-o", str(tmp_path / "o")]) == 2
    assert "--camera and --light go together" in capsys.readouterr().err
    assert main(["invert", "--maps", "--camera", str(tmp_path / "cam.json"), "--light", str(tmp_path / "cam.json"),
                 "-o", str(tmp_path / "o")]) == 2
    assert "need --maps, one --scene" in capsys.readouterr().err


def test_invert_reads_a_linear_camera_exr(tmp_path, capsys):
    """--scene + --reference a mono S0, S1, S2 EXR with sigma (what `stokes` writes): accepted, the
    maps and alpha_seen.npy written."""
    from hyde_bsdf import inverse as inv
    from hyde_bsdf.model.polarimetry import simulate_capture, write_stokes_estimate

    inv.prepare(inv.observations.MAP_VARIANT)
    textured_plane_scene(tmp_path)
    ref = inv.observations.render_stokes_np(inv.scalar.load_scene(str(tmp_path / "s.xml")), 0, 32, seed=1)
    est = simulate_capture(ref, CameraNoise(read_noise=3.0, black_level=64.0), np.random.default_rng(0), signal=3000.0)
    write_stokes_estimate(est, tmp_path / "ref.exr")
    out = tmp_path / "out"
    assert main(["invert", "--maps", "--scene", str(tmp_path / "s.xml"), "--reference", str(tmp_path / "ref.exr"),
                 "--iterations", "3", "--no-uncertainty", "-o", str(out)]) == 0
    assert (out / "alpha.npy").is_file() and set(np.unique(np.load(out / "alpha_seen.npy"))) <= {0.0, 1.0}
