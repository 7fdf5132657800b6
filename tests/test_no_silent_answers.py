"""No silent empty or degenerate answer, and sizes known before memory is taken (issue 33, items 4-5).

Physics and behaviour checked, each with its numbers:

* the pBRDF at the horizon: grazing specular F00 grows as 1/cos^2 theta (Eq. 6's 1/(4 cos ti cos tr)
  with G = 1), F00 cos^2 theta constant to 0.2 % from 89.99 deg down to cos = 1.7e-6; at and within rounding of 90 deg
  (cos <= 1e-15) every element is exactly 0 (was 1.1e31);
* a fit with no more distinct geometries than parameters (or, without sigma, fewer than 10) is never
  "adequate"; a fit at 8 geometries with sigma for 3 parameters still is;
* references no light can give (S0 < 0, DoLP > 1 beyond 5 sigma, bad sigma) are warned with the share
  of pixels and left out, and noise within 2 sigma of DoLP = 1 is not;
* calibrated raw data: pixels darker than the black level beyond 5 read-noise sigma (+ 0.5 DN) are left out and
  warned with their share; all of them, refused;
* masks: NaN is no "use", an all-zero mask is refused; a NaN surface profile is refused before the MoM;
* array files are sized from their headers: a 144-byte .npy claiming 200000 x 200000, a PNG header
  claiming 14000 x 14000 -- one line each, nothing allocated.

Cost: about 3 s on a quiet core (no render, no Mitsuba scene).
"""
import warnings

import numpy as np
import pytest
from conftest import textured_plane_scene

from hyde_bsdf.errors import UsageError


# --- the evaluator at the horizon (last round's 1.1e31) ---------------------------------------------

def test_grazing_specular_grows_as_one_over_cos_squared_and_is_zero_at_the_horizon():
    from hyde_bsdf import pbrdf
    from hyde_bsdf.model.facet_geometry import HORIZON_COS

    deg = np.array([89.0, 89.9, 89.99, 89.9999])
    F00 = pbrdf(np.radians(deg), np.radians(deg), np.pi, rms_slope=0.3, n=1.5)[..., 0, 0]
    limit = F00 * np.cos(np.radians(deg)) ** 2
    assert np.all(np.isfinite(F00)) and F00[-1] > 1e11                   # a real divergence, not rounding
    assert limit[1:] == pytest.approx(limit[-1], rel=2e-2)                 # 0.4376 .. 0.4421
    assert limit[2] == pytest.approx(limit[3], rel=2e-3)
    for theta in (np.pi / 2, np.nextafter(np.pi / 2, 0.0)):               # cos 6.1e-17 and 2.8e-16: rounding
        assert np.cos(theta) < HORIZON_COS
        F = pbrdf(theta, theta, np.pi, rms_slope=0.3, n=1.5)
        assert np.all(F == 0.0)
        assert np.all(pbrdf(np.radians(30.0), theta, np.pi, rms_slope=0.3, n=1.5) == 0.0)


# --- fits that cannot determine their parameters ------------------------------------------------------

def test_too_few_geometries_is_never_adequate():
    from hyde_bsdf.fit.adequacy import MIN_GEOMETRIES, chi2_verdict, floor_verdict, too_few_geometries

    one = np.radians([30.0]), np.radians([30.0]), np.array([np.pi])
    v = too_few_geometries(*one, parameters=3)
    assert not v.adequate and v.figures == {"geometries": 1, "needed": MIN_GEOMETRIES}
    assert "1 distinct geometry cannot determine the 3 fitted parameter(s)" in v.message
    # repeats of one geometry are one geometry
    rep = [np.repeat(a, 50) for a in one]
    assert too_few_geometries(*rep, parameters=1).figures["geometries"] == 1
    # with sigma: more geometries than parameters suffice; 3 for 3 do not
    th = np.radians(np.arange(10.0, 81.0, 10.0))
    assert too_few_geometries(th, th, np.pi, parameters=3, test="chi2") is None
    assert too_few_geometries(th[:3], th[:3], np.pi, parameters=3, test="chi2").figures == {"geometries": 3,
                                                                                           "needed": 4}
    r = np.zeros((4, 3))
    assert not chi2_verdict(3.0, 9, r, th[:3], th[:3], np.pi, parameters=3).adequate
    assert chi2_verdict(29.0, 29, np.zeros((4, 8)), th, th, np.pi, parameters=3).adequate
    # without sigma: the floor test needs MIN_GEOMETRIES (10) geometries
    assert not floor_verdict(None, np.zeros((1, 4, 8)), th, th, np.pi, parameters=3).adequate
    th12 = np.radians(np.linspace(5.0, 80.0, 12))
    assert floor_verdict(None, np.full((1, 4, 12), 1e-3), th12, th12, np.pi, parameters=3).test == "floor"


# --- references no light gives --------------------------------------------------------------------------

def _ref(h=20, w=20):
    ref = np.zeros((4, h, w))
    ref[0], ref[1], ref[2] = 1.0, 0.3, -0.2
    return ref, np.full((4, h, w), 0.01)


def test_impossible_reference_pixels_are_warned_with_their_share():
    from hyde_bsdf.inverse.camera_data import ReferenceDataWarning, impossible_pixels

    ref, sig = _ref()
    ref[1, :5] = 1.5                                         # 25 % of the pixels: DoLP 1.5
    ref[0, 5:7] = -0.2                                       # 10 %: S0 = -0.2 (20 sigma below 0)
    bad_sigma = np.zeros((20, 20), bool)
    bad_sigma[19, :8] = True                                 # 2 %: NaN or negative sigma
    with pytest.warns(ReferenceDataWarning) as rec:
        bad = impossible_pixels(ref, sig, "ref.exr", bad_sigma)
    text = [str(w.message) for w in rec]
    assert any("ref.exr: 25 % of the pixels (100 of 400) have a degree of polarization > 1" in t for t in text)
    assert any("10 % of the pixels (40 of 400) have a negative S0" in t for t in text)
    assert any("2 % of the pixels (8 of 400) have a negative, zero or NaN sigma" in t for t in text)
    assert bad.sum() == 148
    # noise: DoLP = 1 + 2 sigma and S0 = -2 sigma are measurements, not impossible
    ref, sig = _ref()
    ref[:, 0, 0] = -0.02, 0.0, 0.0, 0.0                      # unpolarized, S0 2 sigma below 0
    ref[1:3, 0, 1] = 1.0 + 0.02, 0.0                         # DoLP 1.02, 1 sigma (of |S_lin|: 0.02) above 1
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert not impossible_pixels(ref, sig, "ref.exr").any()


def test_camera_reference_leaves_impossible_pixels_out_of_the_mask():
    from hyde_bsdf.inverse.camera_data import ReferenceDataWarning, camera_reference

    ref, sig = _ref(8, 8)
    ref[1, 0, :4] = 2.0                                      # 4 of 64 pixels: DoLP 2
    sig[2, 7, 7] = np.nan
    data = {**{c: ref[i] for i, c in enumerate(("S0", "S1", "S2"))},
            "sigma": {c: sig[i] for i, c in enumerate(("S0", "S1", "S2"))}}
    with pytest.warns(ReferenceDataWarning) as rec:
        out = camera_reference(data, measured=("S0", "S1", "S2"))
    text = " | ".join(str(w.message) for w in rec)
    assert "6.25 % of the pixels (4 of 64) have a degree of polarization > 1" in text
    assert "1.56 % of the pixels (1 of 64) have a negative, zero or NaN sigma" in text
    assert out["mask"].sum() == 64 - 5 and not out["mask"][0, :4].any() and not out["mask"][7, 7]


# --- calibrated raw data -----------------------------------------------------------------------------------

def test_raw_pixels_below_the_black_level_are_left_out_and_counted():
    from hyde_bsdf.model.polarimetry import CameraNoise, stokes_from_mosaic

    noise = CameraNoise(gain=1.0, read_noise=2.0, black_level=64.0)
    raw = np.full((8, 8), 1064.0)
    raw[0, 0] = 64.0 - 10.0                                  # 5 sigma of read noise: noise, kept
    raw[0, 1] = 64.0 - 11.0                                  # beyond 5 sigma + 0.5 DN: no light
    with pytest.warns(UserWarning, match=r"1\.56 % of the pixels \(1 of 64\) are below the black level 64 DN"):
        est = stokes_from_mosaic(raw, noise=noise)
    assert not est.mask[0, 0] and est.mask.sum() == 15       # the superpixel holding it, of 16
    with pytest.raises(UsageError, match=r"every pixel is below the black level 64 DN .* brightest is 10 DN"):
        stokes_from_mosaic(np.full((8, 8), 10.0), noise=CameraNoise(black_level=64.0))


def test_a_non_finite_analysis_matrix_is_refused():
    from hyde_bsdf.model.polarimetry import stokes_from_frames

    A = np.array([[0.5, 0.5, 0, 0], [0.5, 0, 0.5, 0], [0.5, -0.5, 0, 0.0]])
    A[1, 2] = np.nan
    with pytest.raises(UsageError, match="analysis matrix has NaN or infinite entries"):
        stokes_from_frames(np.full((3, 4, 4), 100.0), analysis=A)


# --- masks and surfaces ----------------------------------------------------------------------------------

@pytest.mark.parametrize("mask, match", [(np.full((4, 4), np.nan), "NaN or infinite values in 16 of 16"),
                                         (np.zeros((4, 4)), "leaves out every pixel"),
                                         (np.full((4, 4), np.inf), "NaN or infinite")])
def test_a_mask_of_nan_or_zeros_is_refused(mask, match):
    from hyde_bsdf.inverse.loss import StokesLoss, as_mask

    with pytest.raises(UsageError, match=match):
        StokesLoss(np.ones((4, 4, 4)), mask=mask)
    assert as_mask(np.eye(4) * 0.5).sum() == 4                # non-zero: use the pixel


def test_a_nan_surface_is_refused_before_the_solve():
    from hyde_bsdf.mom.dense import solve_dense

    x = np.linspace(0.0, 1.0, 8)
    y = np.zeros(8)
    y[5] = np.nan
    with pytest.raises(UsageError, match=r"1 NaN or infinite value\(s\) in the height y \(first at index 5\)"):
        solve_dense(x, y, np.zeros(8), np.zeros(8), x[1], np.ones((8, 1), complex), ("s",), None)


# --- sizes from headers ---------------------------------------------------------------------------------

def test_array_files_are_sized_from_their_headers(tmp_path, monkeypatch):
    import struct
    import zlib

    from hyde_bsdf.io.arrays import array_header, read_array

    lie = tmp_path / "lie.npy"
    with open(lie, "wb") as fh:
        np.lib.format.write_array_header_1_0(fh, {"descr": "<f8", "fortran_order": False, "shape": (200000, 200000)})
        fh.write(b"\0" * 16)
    with pytest.raises(UsageError, match=r"header says 200000x200000 float64 values \(298 GiB\), but the file holds "
                                         r"16 B"):
        read_array(lie, "--mask")
    # a PNG whose header claims 14000 x 14000 grey pixels (196 MB decoded) in 67 bytes
    chunk = lambda kind, data: (struct.pack(">I", len(data)) + kind + data
                                + struct.pack(">I", zlib.crc32(kind + data)))
    png = tmp_path / "bomb.png"
    png.write_bytes(b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", struct.pack(">IIBBBBB", 14000, 14000, 8, 0, 0, 0, 0))
                    + chunk(b"IDAT", zlib.compress(b"\0" * 64)) + chunk(b"IEND", b""))
    assert array_header(png, "frame") == ((14000, 14000), np.dtype(np.uint8))
    monkeypatch.setattr("hyde_bsdf.resources.available_memory", lambda: 64 * 2**20)
    with pytest.raises(UsageError, match=r"frame .*bomb.png. \(14000x14000\): about 187 MiB of memory needed"):
        read_array(png, "frame")
    # Radiance RGBE and PFM textures (Mitsuba's other bitmap formats): sized from their text headers too
    from hyde_bsdf.io.arrays import check_image_memory, image_shape

    (tmp_path / "big.hdr").write_bytes(b"#?RADIANCE\nFORMAT=32-bit_rle_rgbe\n\n-Y 100000 +X 100000\n")
    (tmp_path / "big.pfm").write_bytes(b"PF\n100000 100000\n-1\n")
    assert image_shape(tmp_path / "big.hdr") == (100000, 100000, 3) == image_shape(tmp_path / "big.pfm")
    with pytest.raises(UsageError, match=r"texture .*big.hdr. \(100000x100000x3\): about 112 GiB of memory needed"):
        check_image_memory(tmp_path / "big.hdr", "texture")


def test_npz_and_csv_files_are_sized_before_they_are_decoded(tmp_path, monkeypatch):
    """A .npz: its members' headers, read through zipfile, against the available memory (a 32 MiB array of
    zeros deflates to 32 KiB; 16 MiB available: refused, nothing inflated past the header) and read back
    whole when it fits.  A CSV: at most one value per comma or line end (counted in the bytes, before they
    are decoded) at COSTS.csv_bytes_per_value = 64 B: 50000 rows of 4 one-digit values, 391 KiB, can hold
    200005 values, 12.2 MiB to parse.  Cost: about 0.5 s."""
    from hyde_bsdf.io.arrays import read_npz
    from hyde_bsdf.io.input_gate import check_csv_values
    from hyde_bsdf.io.measurements import MeasurementFileError, read_measurements

    np.savez_compressed(tmp_path / "zeros.npz", z=np.zeros(2**22), one=np.arange(3))
    assert (tmp_path / "zeros.npz").stat().st_size < 2**16
    got = read_npz(tmp_path / "zeros.npz")
    assert sorted(got) == ["one", "z"] and got["z"].shape == (2**22,) and got["one"].tolist() == [0, 1, 2]
    assert check_csv_values(b"a,b\r\n1,2\n3,4", "x") == 7        # an upper bound: 6 cells (CR LF counts twice)
    monkeypatch.setattr("hyde_bsdf.resources.available_memory", lambda: 16 * 2**20)
    with pytest.raises(UsageError, match=r"^atlas .*zeros.npz., 2 arrays \(33554456\): about 32 MiB of memory needed, "
                                         r"but only 16 MiB is available; give a smaller file$"):
        read_npz(tmp_path / "zeros.npz", "atlas")
    csv = tmp_path / "dense.csv"
    csv.write_text("theta_i_deg,theta_r_deg,phi_deg,M01\n" + "1,1,1,0\n" * 50_000)
    assert len(read_measurements(csv)) == 50_000                  # 12.2 MiB of 16: read
    monkeypatch.setattr("hyde_bsdf.resources.available_memory", lambda: 8 * 2**20)
    with pytest.raises(MeasurementFileError, match=r"^measurement file .*dense.csv. \(391 KiB: at most 200005 values, "
                                                   r"64 B each to parse\): about 12\.2 MiB of memory needed, but only "
                                                   r"8 MiB is available; split it into smaller files$"):
        read_measurements(csv)


def test_pbrdf_refuses_a_direction_count_beyond_the_memory(monkeypatch):
    """10^4 x 10^4 broadcast directions need 10^8 x 160 B = 14.9 GiB (COSTS.pbrdf_bytes_per_direction: the
    128 B result and the checks' temporaries; the model itself runs in blocks): with 1 GiB available, one
    line naming the parameters before any allocation (was a MemoryError after 71 s)."""
    from hyde_bsdf import pbrdf

    monkeypatch.setattr("hyde_bsdf.resources.available_memory", lambda: 2**30)
    th = np.linspace(0.0, 1.5, 10**4)
    with pytest.raises(UsageError, match=r"^pbrdf of 100000000 directions \(160 B each, 128 B of it the 4x4 result\): "
                                         r"about 14\.9 GiB of memory needed, but only 1 GiB is available; pass fewer "
                                         r"directions in theta_i, theta_r, phi at once$"):
        pbrdf(th[:, None], th[None, :], np.pi, rms_slope=0.3, n=1.5)
    assert pbrdf(th[:100], th[:100], np.pi, rms_slope=0.3, n=1.5).shape == (100, 4, 4)   # small: unchecked


def test_pbrdf_memory_beyond_its_result_is_bounded():
    """The model runs in blocks of 8192 directions and never expands broadcast angles: at 10^6 broadcast
    directions (1000 x 1000) the peak beyond the 122 MiB result is 2.1 MiB (tracemalloc; was 33.4 MiB,
    growing with the count), asserted < 8 MiB.  Cost: about 1 s."""
    import tracemalloc

    from hyde_bsdf import pbrdf

    th = np.linspace(0.0, 1.5, 1000)
    pbrdf(th[:3], th[:3], np.pi, rms_slope=0.3, n=1.5)          # the DHR table read once, outside the count
    tracemalloc.start()
    try:
        F = pbrdf(th[:, None], th[None, :], np.pi, rms_slope=0.3, n=1.5)
        beyond = tracemalloc.get_traced_memory()[1] - F.nbytes
    finally:
        tracemalloc.stop()
    assert F.shape == (1000, 1000, 4, 4) and F.nbytes == 128 * 10**6
    assert beyond < 8 * 2**20, beyond / 2**20


# --- calibration files: one line, never a library's exception --------------------------------------

def test_camera_files_that_no_pinhole_has(tmp_path):
    import json

    from hyde_bsdf.render.camera import load_cameras

    cam = {"width": 16, "height": 16, "fx": 20.0, "fy": 20.0, "cx": 7.5, "cy": 7.5,
           "R": [[1, 0, 0], [0, 1, 0], [0, 0, 1]], "t": [0, 0, 4]}
    path = tmp_path / "cam.json"
    for fx, fov in ((1e-300, "180"), (1e300, "9.16732e-298"), (0.01, "179.857")):
        path.write_text(json.dumps({**cam, "fx": fx, "fy": fx}))
        with pytest.raises(UsageError, match=rf"field of view of {fov} deg; a pinhole camera's is in \[0\.001, 179\]"):
            load_cameras(path)
    path.write_text(json.dumps(cam))
    assert load_cameras(path)[0].fx == 20.0                # 43.6 deg: accepted
    path.write_text("[" * 100_000)                         # nested beyond Python's recursion limit
    with pytest.raises(UsageError, match="nested too deeply"):
        load_cameras(path)


def test_an_unexpected_library_exception_is_one_line_and_exit_2(monkeypatch, capsys):
    """A NumPy LinAlgError raised inside a command (a stand-in for any library's exception): one line
    naming its type and where in the package, exit 2; HYDE_BSDF_TRACEBACK=1 gives the traceback back."""
    from hyde_bsdf.app import cli

    def boom(argv):
        np.linalg.inv(np.zeros((2, 2)))

    monkeypatch.setattr("hyde_bsdf.app.export.cli_main", boom)
    assert cli.main(["export", "x.pbsdf"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "Traceback" not in err[0]
    assert err[0].startswith("hyde-bsdf export: error: LinAlgError: Singular matrix (unexpected in ")
    assert "HYDE_BSDF_TRACEBACK=1 shows the traceback" in err[0]
    monkeypatch.setattr("hyde_bsdf.app.export.cli_main", lambda argv: [0] * (2**62))
    assert cli.main(["export", "x.pbsdf"]) == 2
    assert "error: out of memory" in capsys.readouterr().err
    monkeypatch.setenv("HYDE_BSDF_TRACEBACK", "1")
    monkeypatch.setattr("hyde_bsdf.app.export.cli_main", boom)
    with pytest.raises(np.linalg.LinAlgError):
        cli.main(["export", "x.pbsdf"])


# --- a camera that sees no texel -------------------------------------------------------------------------

def test_maps_of_a_sample_no_camera_sees_are_refused_before_the_work(tmp_path, capsys, monkeypatch):
    """The sensor looks away from the textured plane: 'texels seen 0 of 4', exit 2, nothing written
    (was all-NaN maps and exit 0)."""
    from hyde_bsdf import inverse as inv
    from hyde_bsdf.app.cli import main
    from hyde_bsdf.io.stokes_exr import write_stokes_exr

    inv.prepare(inv.observations.MAP_VARIANT)
    textured_plane_scene(tmp_path, target="0, -6, 6", size=8)      # looking up, away from the plane
    S = np.zeros((8, 8, 3), np.float32)
    write_stokes_exr(tmp_path / "ref.exr", {"S0": S + 1.0, "S1": S + 0.1, "S2": S, "S3": S})
    monkeypatch.setattr("hyde_bsdf.inverse.maps._polish", None)     # any step of the work would fail
    out = tmp_path / "out"
    assert main(["invert", "--maps", "--scene", str(tmp_path / "s.xml"), "--reference", str(tmp_path / "ref.exr"),
                 "--iterations", "2", "--no-uncertainty", "-o", str(out)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert "no picture sees the sample: texels seen 0 of 4" in err[-1]
    assert not (out / "alpha.npy").exists()


def test_model_selection_does_not_advise_itself():
    """A fixed model's inadequate verdict advises model selection ('--model auto'); once every model was tried (auto
    mode) the advice is dropped -- the rest of the message, its figures and cause, stay."""
    from hyde_bsdf.fit.adequacy import MODEL_ADVICE, chi2_verdict, without_advice

    th = np.radians(np.linspace(10.0, 80.0, 24))
    r = np.tile(np.linspace(-3.0, 3.0, 24), (4, 1))           # a trend: structured misfit
    v = chi2_verdict(float((r ** 2).sum()), 4 * 24 - 3, r, th, th, np.pi, parameters=3)
    assert not v.adequate and v.message.endswith(MODEL_ADVICE)
    text = v.message
    assert without_advice(v).message == text[: -len(MODEL_ADVICE)] and "select_model" not in v.message


def test_stokes_checks_the_estimate_after_calibration(tmp_path, capsys):
    """Three frames behind 0/60/120 deg analyzers reading 200, 0, 0 DN in 2 of 16 pixels: the least-squares
    Stokes vector there is S0 = 133, S1 = 267 -- a degree of polarization of 2 (a scene that moved, a wrong
    angle), 17 sigma beyond 1: warned with its share, mask 0 in the EXR; the other 14 pixels pass."""
    from hyde_bsdf.app.cli import main
    from hyde_bsdf.io.stokes_exr import read_camera_stokes

    frames = [np.full((4, 4), 100.0) for _ in range(3)]
    frames[0][0, :2], frames[1][0, :2], frames[2][0, :2] = 200.0, 0.0, 0.0
    names = [tmp_path / f"f{i}.npy" for i in range(3)]
    for name, f in zip(names, frames):
        np.save(name, f)
    out = tmp_path / "s.exr"
    assert main(["stokes", "--frames", *map(str, names), "--angles", "0,60,120", "--read-noise", "2", "-q",
                 "-o", str(out)]) == 0
    err = capsys.readouterr().err
    assert "the Stokes estimate of the 3 --frames: 12.5 % of the pixels (2 of 16) have a degree of polarization > 1" \
        in err
    d = read_camera_stokes(out)
    dolp = np.hypot(d["stokes"]["S1"], d["stokes"]["S2"])[..., 0] / d["stokes"]["S0"][..., 0]
    assert dolp[0, :2] == pytest.approx(2.0, rel=1e-6) and d["mask"].sum() == 14 and not d["mask"][0, :2].any()
