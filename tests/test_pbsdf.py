"""Measured pBRDF tables (Mitsuba ``measured_polarized``): reading, frames, export, refusal, round trip.

Physics and format checked:
- the reader on files the exporter wrote: every usable node, converted to the paper's angles
  and Stokes bases, equals ``hyde_bsdf.pbrdf`` there to float32 rounding (2e-6 relative);
- the reader on hand-built tables with NaN, negative-M00 and over-polarized cells: the counts
  are exact and no such cell reaches the fit;
- the frame conversion against Mitsuba's own C++ ``measured_polarized`` eval (scalar variant),
  rotated into the paper's bases by ``hyde_bsdf.validation._frames.eval_paper``: the NumPy lookup
  replica in the paper's bases equals it to 1e-4 (float32 interpolation), including the NaN
  quirks (a NaN in M00 at a corner blacks out the matrix, a NaN elsewhere makes it all NaN);
- Mitsuba's C++ eval of an exported file against the Python ``hyde`` plugin: the error
  statistics equal those the export reported (same geometries) to 3 % of themselves;
- the refusal of tables larger than Mitsuba's 32-bit index, the free disk or the memory,
  before any file is created;
- the round trip export -> read -> fit recovers n, k per band and rms_slope to 1e-4;
- the export's colour (issue 31): the colour error of every row of the tutorial's table (bands chosen
  by colour error, the projected index) recomputed at its bands equals the documented one to 0.01 %,
  a search reproduces gold's documented bands, and a rendered flat patch of gold (C++ table against
  the Python plugin, same seed) keeps each sRGB channel within 1 %, where the index sampled at
  450-650 nm gives B > +4 %.
"""
import math

import json

import numpy as np
import pytest

from hyde_bsdf import pbrdf
from hyde_bsdf.app.cli import main
from hyde_bsdf.errors import UsageError
from hyde_bsdf.model.terms import RENDER_DEFAULT
from hyde_bsdf.fit.pbsdf_export import (_query_geometries, check_table_size, error_statistics,
                                        export_pbsdf, grids)
from hyde_bsdf.io.pbsdf_file import (PbsdfFileError, directions_to_rusinkiewicz, read_pbsdf,
                                     rusinkiewicz_to_directions, write_pbsdf)
from hyde_bsdf.fit.pbsdf_samples import paper_angles, paper_to_table, pbsdf_samples, table_to_paper

PARAMS = dict(rms_slope=0.25, n=[1.4, 1.0, 0.6, 0.4, 0.3], k=[1.9, 2.2, 2.6, 3.0, 3.3])
RES = (13, 9, 11)


@pytest.fixture(scope="module")
def exported(tmp_path_factory):
    path = tmp_path_factory.mktemp("pbsdf") / "gold.pbsdf"
    report = export_pbsdf(path, **PARAMS, resolution=RES, error_samples=1500, alpha_sample=0.3)
    return path, report


def _mitsuba():
    mi = pytest.importorskip("mitsuba")
    from hyde_bsdf.mitsuba.variants import set_variant
    set_variant("scalar_spectral_polarized", fallback=False)
    return mi


def _paper_axes(pi_, pr):
    return (np.stack([-np.sin(pi_), np.cos(pi_), 0 * pi_], -1),
            np.stack([np.sin(pr), -np.cos(pr), 0 * pr], -1))


# --------------------------------------------------------------------------------- the reader

def test_reader_on_an_exported_file_gives_the_model_at_every_node(exported):
    path, report = exported
    t = read_pbsdf(path)
    assert t.M.shape == (*RES, 5, 4, 4) and t.M.dtype == np.float32
    assert t.wavelengths.tolist() == [450, 500, 550, 600, 650]
    pd, td, th = grids(RES)
    assert np.allclose(t.phi_d, pd, atol=1e-6) and t.phi_d[0] == pytest.approx(-math.pi, abs=1e-6)
    assert np.allclose(t.theta_h, th, atol=1e-6) and np.all(np.diff(t.theta_h, 2) > 0)   # dense near 0
    assert np.isfinite(np.asarray(t.M)).all()          # below-horizon cells filled, never NaN
    meta = t.extra["hyde_export"]
    assert meta["rms_slope"] == 0.25 and meta["n"] == PARAMS["n"] and meta["alpha_sample"] == 0.3
    assert meta["errors"]["m00_l1"] == pytest.approx(report.errors["m00_l1"])
    s = pbsdf_samples(t, max_points=10**6, theta_max=math.radians(80))
    assert s.counts.nonfinite == 0 and s.counts.nonphysical == 0
    assert s.counts.total == int(np.prod(RES)) * 5
    assert len(s) == s.usable_geometries > 100
    assert np.all(s.theta_i <= math.radians(80) + 1e-9) and np.all(s.theta_r <= math.radians(80) + 1e-9)
    for b in range(5):
        F = pbrdf(s.theta_i, s.theta_r, s.phi, rms_slope=0.25, n=PARAMS["n"][b], k=PARAMS["k"][b],
                  shadowing=RENDER_DEFAULT[0], diffuse=RENDER_DEFAULT[1])     # the export's default model
        err = np.abs(s.F[b] - F).max(axis=(1, 2)) / F[:, 0, 0]
        assert err.max() < 2e-6, (b, err.max())


def test_rusinkiewicz_coordinates_round_trip():
    rng = np.random.default_rng(3)
    pd, td, th = rng.uniform(-3.1, 3.1, 200), rng.uniform(0.01, 1.5, 200), rng.uniform(0.01, 1.5, 200)
    om_i, om_r, x = rusinkiewicz_to_directions(pd, td, th)
    back = directions_to_rusinkiewicz(om_i, om_r)
    assert np.allclose(back, (pd, td, th), atol=1e-9)
    assert np.allclose(x, np.cross(om_i, om_r) / np.linalg.norm(np.cross(om_i, om_r), axis=-1, keepdims=True))
    F = pbrdf(*paper_angles(om_i, om_r)[:3], rms_slope=0.3, n=1.5, k=0.0)
    assert np.allclose(table_to_paper(paper_to_table(F, om_i, om_r), om_i, om_r), F, atol=1e-12)


def _hand_table(path, M):
    write_pbsdf(path, theta_h=np.linspace(0, 1.5, M.shape[2]), theta_d=np.linspace(0, 1.5, M.shape[1]),
                phi_d=np.linspace(-math.pi, math.pi, M.shape[0]), wavelengths=[450, 500, 550, 600, 650][:M.shape[3]],
                M=M)


def test_reader_masks_nan_and_nonphysical_cells_and_counts_them(tmp_path):
    shape = (5, 6, 7, 2)
    M = np.zeros(shape + (4, 4), np.float32)
    M[..., 0, 0] = 1.0
    M[..., 1, 1] = M[..., 2, 2] = 0.5
    M[1, 2, 3, 0, 2, 1] = np.nan          # NaN in one element of one band
    M[2, 1, 1, 1] = np.nan                # a whole NaN matrix
    M[3, 3, 2, 0, 0, 0] = -0.1            # negative intensity
    M[0, 1, 4, 1, 0, 1] = 1.3             # diattenuation > 1
    M[4, 2, 2, 0, 1, 2] = -1.2            # |M_jk| > M00
    path = tmp_path / "hand.pbsdf"
    _hand_table(path, M)
    t = read_pbsdf(path)
    om_i, om_r, _ = t.grid_directions()
    up = (om_i[..., 2] > 1e-12) & (om_r[..., 2] > 1e-12)
    s = pbsdf_samples(t, max_points=10**6, theta_max=math.pi / 2)
    bad = [(1, 2, 3), (2, 1, 1), (3, 3, 2), (0, 1, 4), (4, 2, 2)]
    assert all(up[c] for c in bad)        # the defects sit above the horizon, so they are counted
    c = s.counts
    assert c.total == int(np.prod(shape))
    assert c.below_horizon == int((~up).sum()) * 2
    assert c.nonfinite == 2 and c.nonphysical == 3
    assert c.detail["M00 <= 0"] == 1 and c.detail["|M_jk| > M00"] == 2 and c.detail["diattenuation > 1"] == 1
    assert c.usable == c.total - c.below_horizon - 5
    kept = {tuple(x) for x in s.cells}
    assert not kept & set(bad)
    assert np.isfinite(s.F).all() and (s.F[..., 0, 0] > 0).all()
    assert "2 with NaN/inf" in c.summary()


def test_subsampling_is_deterministic_and_bounded(exported):
    path, _ = exported
    a = pbsdf_samples(path, max_points=50, seed=4)
    b = pbsdf_samples(path, max_points=50, seed=4)
    c = pbsdf_samples(path, max_points=50, seed=5)
    assert len(a) == 50 and np.array_equal(a.cells, b.cells) and not np.array_equal(a.cells, c.cells)
    assert len(a.measurements(2).values) == 15


@pytest.mark.parametrize("damage, message", [
    (lambda raw: b"not_a_tensor" + raw[12:], "not a Mitsuba tensor file"),
    (lambda raw: raw[: len(raw) // 2], "truncated"),
])
def test_reader_refuses_broken_files_naming_them(exported, tmp_path, damage, message):
    path, _ = exported
    bad = tmp_path / "broken.pbsdf"
    bad.write_bytes(damage(path.read_bytes()))
    with pytest.raises(PbsdfFileError, match=message) as info:
        read_pbsdf(bad)
    assert "broken.pbsdf" in str(info.value)


def test_reader_refuses_a_table_mitsuba_would_refuse(tmp_path):
    from hyde_bsdf.io.pbsdf_file import _header
    layout = {n: (np.dtype(np.float64 if n == "theta_h" else np.float32), (1, 3)) for n in ("theta_h", "theta_d", "phi_d")}
    layout["wvls"] = (np.dtype(np.uint16), (5,))
    layout["M"] = (np.dtype(np.float32), (3, 3, 3, 5, 4, 4))
    head, _, total = _header(layout)
    p = tmp_path / "f64.pbsdf"
    p.write_bytes(head.ljust(total, b"\0"))
    with pytest.raises(PbsdfFileError, match="'theta_h' must be float32"):
        read_pbsdf(p)


# --------------------------------------------------------------- against Mitsuba's C++ plugin

def test_frames_and_lookup_match_mitsubas_measured_polarized(exported, tmp_path):
    mi = _mitsuba()
    from hyde_bsdf.validation._frames import eval_paper

    path, _ = exported
    t = read_pbsdf(path)
    bsdf = mi.load_dict({"type": "measured_polarized", "filename": str(path)})
    om_i, om_r, _ = _query_geometries(400, 0.25, np.random.default_rng(11))
    _, _, _, pi_, pr = paper_angles(om_i, om_r)
    s_i, s_r = _paper_axes(pi_, pr)
    for wl in (500.0, 575.0):               # a band centre and between two bands
        A = eval_paper(bsdf, om_i, om_r, s_i, s_r, wavelength=wl)
        N = table_to_paper(t.interpolate_directions(om_i, om_r, wl), om_i, om_r)
        err = np.abs(A - N).max(axis=(1, 2)) / np.maximum(N[:, 0, 0], 1e-3)
        assert err.max() < 1e-4, (wl, err.max())
    # the NaN quirk: a NaN anywhere in a corner matrix blacks out every query that touches it
    M = np.zeros((5, 6, 7, 5, 4, 4), np.float32)
    M[..., 0, 0] = 1.0
    M[..., 1, 1] = M[..., 2, 2] = M[..., 3, 3] = 0.5
    M[2, 2, 3, 2, 0, 0] = np.nan
    hand = tmp_path / "nan.pbsdf"
    _hand_table(hand, M)
    th_ = read_pbsdf(hand)
    pd = np.array([0.1, 0.1]); td = np.array([0.45, 0.9]); thh = np.array([0.8, 0.2])
    oi, orr, _ = rusinkiewicz_to_directions(pd, td, thh)
    _, _, _, pi_, pr = paper_angles(oi, orr)
    s_i, s_r = _paper_axes(pi_, pr)
    A = eval_paper(mi.load_dict({"type": "measured_polarized", "filename": str(hand)}), oi, orr, s_i, s_r,
                   wavelength=550.0)
    N = table_to_paper(th_.interpolate_directions(oi, orr, 550.0), oi, orr)
    assert np.all(A[0] == 0) and np.all(N[0] == 0)          # touches the NaN node
    assert A[1, 0, 0] == pytest.approx(1.0, rel=1e-5) and np.allclose(A[1], N[1], atol=1e-5)
    # ... but a NaN in another element is not caught: the whole matrix turns NaN, in both
    M[2, 2, 3, 2, 0, 0] = 1.0
    M[2, 2, 3, 2, 2, 1] = np.nan
    _hand_table(hand, M)
    A = eval_paper(mi.load_dict({"type": "measured_polarized", "filename": str(hand)}), oi, orr, s_i, s_r,
                   wavelength=550.0)
    N = table_to_paper(read_pbsdf(hand).interpolate_directions(oi, orr, 550.0), oi, orr)
    assert np.isnan(A[0]).all() and np.isnan(N[0]).all() and np.isfinite(A[1]).all()


def test_cpp_eval_of_the_export_agrees_with_the_hyde_plugin_within_the_reported_error(exported):
    mi = _mitsuba()
    import hyde_bsdf
    from hyde_bsdf.validation._frames import eval_paper

    hyde_bsdf.register("scalar_spectral_polarized")
    path, report = exported
    table = mi.load_dict({"type": "measured_polarized", "filename": str(path)})
    b = 1
    plugin = mi.load_dict({"type": "hyde", "rms_slope": 0.25, "eta": PARAMS["n"][b], "k": PARAMS["k"][b]})
    om_i, om_r, w = _query_geometries(1500, 0.25, np.random.default_rng(0))   # the export's geometries
    _, _, _, pi_, pr = paper_angles(om_i, om_r)
    s_i, s_r = _paper_axes(pi_, pr)
    A = eval_paper(table, om_i, om_r, s_i, s_r, wavelength=500.0)
    B = eval_paper(plugin, om_i, om_r, s_i, s_r, wavelength=500.0)
    got = error_statistics(A, B, w)
    want = report.errors["by_band"][500]
    for key in ("m00_l1", "m00_p95", "pol_median", "pol_p95"):
        assert got[key] == pytest.approx(want[key], rel=0.03, abs=2e-5), key
    assert 0.002 < want["m00_l1"] < 0.2        # a coarse table: a real, visible error


# ---------------------------------------------------------------------------------- refusal

def _machine(monkeypatch, disk, memory):
    """A machine whose disk has ``disk`` bytes free and ``memory`` bytes available."""
    import shutil
    usage = shutil.disk_usage(".")
    monkeypatch.setattr(shutil, "disk_usage", lambda path: usage._replace(free=disk))
    monkeypatch.setattr("hyde_bsdf.resources.available_memory", lambda: memory)


def test_oversize_tables_are_refused_before_any_work(tmp_path, capsys, monkeypatch):
    out = tmp_path / "big.pbsdf"
    with pytest.raises(UsageError, match="32-bit index"):
        export_pbsdf(out, rms_slope=0.3, n=1.5, resolution=(2048, 1024, 1024))
    with monkeypatch.context() as m:
        _machine(m, 10_000_000, 10**12)
        with pytest.raises(UsageError, match="free"):
            check_table_size(out, (145, 37, 37))
        _machine(m, 10**12, 50_000_000)
        with pytest.raises(UsageError, match="memory"):
            check_table_size(out, (145, 37, 37))
        _machine(m, 10**12, 10**12)
        assert check_table_size(out, (145, 37, 37)) == pytest.approx(63.5e6, rel=0.01)
    assert list(tmp_path.iterdir()) == []       # nothing written, no temporary left
    code = main(["export", str(out), "--rms-slope", "0.3", "--n", "1.5", "--resolution", "4000x2000x2000", "-q"])
    err = capsys.readouterr().err
    assert code == 2 and err.count("\n") == 1 and "32-bit" in err
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("kwargs, message", [
    (dict(rms_slope=0.3, n=[1, 2]), "one per band"),
    (dict(rms_slope=0.3, material="Unobtainium"), "data/ior"),
    (dict(rms_slope=-1, n=1.5), "rms_slope"),
    (dict(rms_slope=0.3, n=1.5, resolution="10x10"), "resolution"),
])
def test_export_arguments_are_checked(tmp_path, kwargs, message):
    with pytest.raises(UsageError, match=message):
        export_pbsdf(tmp_path / "x.pbsdf", **kwargs)
    assert not (tmp_path / "x.pbsdf").exists()


# ---------------------------------------------------------------------------------- round trip

def test_round_trip_export_read_fit_recovers_the_parameters(exported):
    from hyde_bsdf.fit.pbsdf_fit import fit_pbsdf

    path, _ = exported
    data = pbsdf_samples(path, max_points=150, seed=1)
    result = fit_pbsdf(data, rms_slope=0.4, shadowing=RENDER_DEFAULT[0], diffuse=RENDER_DEFAULT[1], progress=False)
    assert result.success and not result.warnings
    assert result.rms_slope == pytest.approx(0.25, rel=1e-4)
    assert np.allclose(result.n, PARAMS["n"], rtol=1e-4) and np.allclose(result.k, PARAMS["k"], rtol=1e-4)
    xml = result.plugin_xml()
    assert result.stderr["rms_slope"] < 1e-4 and "spectrum" in xml
    # the index at the table's bands, the end values held out to Mitsuba's 360-830 nm (else 0 there in
    # spectral variants, a wrong colour in RGB ones) -- explicitly: the XML says where it extrapolates
    first, last = (f"{w:g}" for w in (result.wavelengths[0], result.wavelengths[-1]))
    assert f'"360:{result.n[0]:.6g}, {first}:{result.n[0]:.6g}' in xml
    assert f'{last}:{result.n[-1]:.6g}, 830:{result.n[-1]:.6g}"' in xml
    assert f"over 360-{first} and {last}-830 nm the end values are held (an extrapolation, not measured" in xml


def test_a_table_misfit_from_a_held_roughness_is_blamed_on_it(exported):
    """Issue 30 item 3 for tables: rms_slope held at 0.4 on a table made at 0.25 misfits M00 by far;
    the verdict names the held parameter and the value it takes when fitted (0.25 to 1e-3) -- not the
    lobe's shape or the terms it would otherwise suspect.  Two small fits, ~3 s."""
    import warnings

    from hyde_bsdf.fit.pbsdf_fit import fit_pbsdf

    path, _ = exported
    data = pbsdf_samples(path, max_points=150, seed=1)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        held = fit_pbsdf(data, fit=("n", "k"), rms_slope=0.4, shadowing=RENDER_DEFAULT[0],
                         diffuse=RENDER_DEFAULT[1], progress=False)        # the table's terms (the export's default)
    assert not held.verdict.adequate and held.verdict.message.startswith("M00 misfit")
    assert "the parameter(s) held fixed (rms_slope = 0.4) cause the misfit" in held.verdict.message
    fitted = float(held.verdict.message.split("(rms_slope = ")[2].split(")")[0])
    assert fitted == pytest.approx(0.25, rel=1e-3)


def test_fit_cli_on_a_pbsdf_file(exported, tmp_path, capsys):
    path, _ = exported
    js = tmp_path / "fit.json"
    code = main(["fit", str(path), "--max-points", "40", "--n0", "0.6", "--k0", "2.6", "--json", str(js), "-q"])
    out = capsys.readouterr().out
    assert code == 0
    assert "rms_slope = 0.25" in out and "0 with NaN/inf" in out and '<bsdf type="hyde">' in out
    # issue 30 item 4 for tables: the lab fit's JSON schema, n and k per band at its wavelength
    d = json.loads(js.read_text())
    assert set(d) == {"model", "parameters", "covariance", "verdict", "models"}
    bands = [p["wavelength_nm"] for p in d["parameters"] if p["name"] == "n"]
    assert len(bands) == 5 and d["parameters"][-1]["name"] == "rms_slope"
    assert d["parameters"][-1]["value"] == pytest.approx(0.25, rel=1e-3)
    assert np.shape(d["covariance"]["matrix"]) == (11, 11) and len(d["covariance"]["names"]) == 11
    assert sum(m["chosen"] for m in d["models"]) == 1 and d["verdict"]["p_value"] is None
    assert main(["fit", str(path), "--tolerance", "2", "-q"]) == 2          # refused before fitting
    assert "tolerance" in capsys.readouterr().err
    assert main(["fit", str(tmp_path / "missing.pbsdf")]) == 2
    err = capsys.readouterr().err
    assert "missing.pbsdf" in err and err.count("\n") == 1


def test_alpha_sample_suggestion_uses_mitsubas_own_sampling_density(exported):
    """The NumPy density the suggestion minimizes the variance with is measured_polarized's pdf()."""
    mi = _mitsuba()
    import drjit as dr
    from hyde_bsdf.fit.pbsdf_export import _ggx_pdf, suggest_alpha_sample
    from hyde_bsdf.fit.pbsdf_export import band_index

    # Mitsuba's data/ior is found once mitsuba is imported too (the module is then its alias .so)
    assert band_index(material="Au")[0][2] == pytest.approx(0.3504, abs=1e-3)

    path, _ = exported
    rng = np.random.default_rng(5)
    wi = rusinkiewicz_to_directions(0.0, rng.uniform(0.05, 1.3, 30), 0.0)[0]
    wo = rusinkiewicz_to_directions(0.0, rng.uniform(0.05, 1.3, 30), 0.0)[0]
    wo = np.stack([wo[:, 0] * np.cos(1.1) - wo[:, 1] * np.sin(1.1), wo[:, 0] * np.sin(1.1) + wo[:, 1] * np.cos(1.1), wo[:, 2]], -1)
    for alpha in (0.05, 0.3):
        bsdf = mi.load_dict({"type": "measured_polarized", "filename": str(path), "alpha_sample": alpha})
        ctx = mi.BSDFContext()
        got = []
        for a, b in zip(wi, wo):
            si = dr.zeros(mi.SurfaceInteraction3f)
            si.wi = mi.Vector3f(*a)
            got.append(float(bsdf.pdf(ctx, si, mi.Vector3f(*b))))
        want = _ggx_pdf(wi.astype(np.float32).astype(float), wo.astype(np.float32).astype(float), alpha)
        assert np.allclose(got, want, rtol=2e-4, atol=1e-6), alpha
    params = dict(rms_slope=0.3, n=PARAMS["n"], k=PARAMS["k"], shadowing="vgroove", diffuse="paper")
    alpha, score = suggest_alpha_sample(params, n_theta=80, n_phi=80)
    assert 0.15 <= alpha <= 0.6 and score[alpha] <= min(score[0.005], score[1.0]) / 2


# --------------------------------------------------------------------------------- the export's colour

def _colour_table():
    """{material: (bands, [R, G, B] %)} of docs/tutorials/pbsdf.md's table of the export's colour."""
    import re
    from pathlib import Path

    text = (Path(__file__).resolve().parents[1] / "docs" / "tutorials" / "pbsdf.md").read_text(encoding="utf-8")
    rows = {}
    for names, _, bands, err in re.findall(r"^\| ([\w\-, ]+) \| ([\d–]+) \| ([\d, ]+) \| ([\d. /]+) \| [\d.]+ \|$",
                                           text, flags=re.M):
        for name in names.split(", "):
            rows[name] = (tuple(int(b) for b in bands.split(", ")), [float(e) for e in err.split(" / ")])
    return rows


def test_tutorial_colour_table_is_what_the_export_computes():
    """Every row (each of Mitsuba's data/ior names): the colour error at the documented bands, projected
    index, recomputed (0.01 % = the table's rounding); within 1 % except the two tables the page explains
    (AlAs: a gap of n = 0 in Mitsuba's data; AlSb: ends at 590 nm); a search reproduces gold's bands."""
    from hyde_bsdf.fit.pbsdf_bands import choose_bands, index_spectrum
    from hyde_bsdf.io.ior import known_materials

    rows = _colour_table()
    assert sorted(rows) == sorted(known_materials())
    for name, (bands, documented) in rows.items():
        got = 100 * np.array(choose_bands(index_spectrum(name), bands).colour_error)
        assert np.allclose(got, documented, atol=0.0051), (name, got, documented)
        if not name.startswith(("AlAs", "AlSb")):
            assert max(documented) <= 1.0, name
    assert choose_bands(index_spectrum("Au")).wavelengths == rows["Au"][0]


def test_rendered_flat_patch_of_an_exported_metal_keeps_its_colour(tmp_path):
    """Gold, rms_slope 0.3, a 13x25x25 table near the specular peak (theta_i 40, theta_r 50 deg): the C++
    table's render / the Python plugin's - 1 per sRGB channel within 1 % with the chosen bands (measured
    -0.1 %); the index sampled at 450-650 nm is bluer by > 4 % (measured +5.4 %): the check can fail."""
    import importlib.util
    from pathlib import Path

    from hyde_bsdf.fit.pbsdf_bands import choose_bands, index_spectrum

    spec = importlib.util.spec_from_file_location(
        "pbsdf_export_validation", Path(__file__).resolve().parents[1] / "hyde_bsdf" / "validation" / "pbsdf_export.py")
    v = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(v)
    rel = {}
    for how, bands in (("chosen", None),
                       ("sampled", choose_bands(index_spectrum("Au"), (450, 500, 550, 600, 650), "sampled"))):
        path = tmp_path / f"{how}.pbsdf"
        export_pbsdf(path, rms_slope=0.3, material="Au", resolution=(13, 25, 25), error_samples=0,
                     alpha_sample=0.3, bands=bands)
        rel[how] = v.patch_colour(path, "Au", 0.3, v.PATCH_GEOMETRIES[:1], spp=16)[0][2]
    assert np.all(np.abs(rel["chosen"]) <= 0.01), rel
    assert rel["sampled"][2] > 0.04, rel


@pytest.mark.parametrize("args, message", [
    (["export", "{tmp}", "--rms-slope", "0.3", "--n", "1.5"], "is a directory"),
    (["export", "{tmp}/a.pbsdf", "--rms-slope", "0.3", "--n", "1.5", "--wavelengths", "400,500"], "wavelengths must be 5"),
    (["export", "{tmp}/a.pbsdf", "--rms-slope", "0.3", "--n", "1.5", "--band-index", "sampled"], "--band-index"),
    (["export", "{tmp}/a.pbsdf", "--rms-slope", "0.3", "--n", "1.5", "--resolution", "10x10"], "resolution"),
    (["export", "{tmp}/a.pbsdf", "--n", "1.5"], "--rms-slope"),
    (["export", "{tmp}/a.pbsdf", "--rms-slope", "0.3", "--material", "Au", "--n", "1"], "either material or n"),
    (["export", "{tmp}/a.pbsdf", "--rms-slope", "0.3", "--n", "1.5,x"], "--n must be"),
    (["fit", "{tmp}/text.pbsdf"], "not a Mitsuba tensor file"),
    (["fit", "{tmp}/text.pbsdf", "--fit", "n,q"], "fit must be"),
    (["fit", "{tmp}/text.pbsdf", "--theta-max", "95"], "--theta-max"),
])
def test_cli_mistakes_are_one_line_exit_2_and_write_nothing(tmp_path, capsys, args, message):
    (tmp_path / "text.pbsdf").write_text("theta_i_deg,theta_r_deg\n")
    before = sorted(p.name for p in tmp_path.iterdir())
    code = main([a.replace("{tmp}", str(tmp_path)) for a in args])
    err = capsys.readouterr().err
    assert code == 2 and message in err and err.count("\n") == 1, err
    assert sorted(p.name for p in tmp_path.iterdir()) == before
