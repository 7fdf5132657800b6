"""Lab Mueller data (issue 30): M00 in 1/sr, several wavelengths, values judged against their sigmas,
the joint fit of everything the data determine, the JSON result, honest verdicts.

Physics checked: the model evaluated through its prepared factors (angles once, lobe per roughness,
Fresnel per index) equals pbrdf to rounding; the joint fit of a two-wavelength Beckmann + Smith +
Lambertian surface recovers the generating roughness, index and albedo within 4 standard errors;
a misfit caused by a roughness held at a wrong value is blamed on that parameter, not the sigmas;
without M00 the roughness is reported as seen only through the diffuse term (and not at all
without one).  Cost: about 10 s (a dozen small fits).
"""
from __future__ import annotations

import json
import math

import numpy as np
import pytest

from hyde_bsdf import pbrdf
from hyde_bsdf.app.cli import main
from hyde_bsdf.fit.lab import fit_lab
from hyde_bsdf.io.measurements import MeasurementFileError, Measurements, read_measurements, write_measurements
from hyde_bsdf.model.prepared import PreparedGeometry

ELEMENTS = ("M01", "M10", "M11", "M12", "M22", "M23", "M32", "M33")
TRUTH = {"rms_slope": 0.21, "albedo": 0.05, 632.8: (1.3, 7.0), 1550.0: (0.9, 11.0)}


def geometry(n=60, seed=0):
    """Goniometer geometries in and out of the plane of incidence (degrees 5-75, any azimuth)."""
    g = np.random.default_rng(seed)
    return np.radians(g.uniform(5, 75, n)), np.radians(g.uniform(5, 75, n)), np.radians(g.uniform(0, 360, n))


def lab_measurements(with_m00=True, seed=1, n=60, shadowing="smith"):
    """Two wavelengths of Beckmann + Smith + Lambertian data, noise 1 % of M00 + 0.002 1/sr per element."""
    rng = np.random.default_rng(seed)
    ti, tr, ph = geometry(n)
    geo = PreparedGeometry(ti, tr, ph)
    parts = []
    for wl in (632.8, 1550.0):
        F = geo.mueller(TRUTH["rms_slope"], *TRUTH[wl], shadowing, "lambertian", TRUTH["albedo"])
        noise = 0.01 * F[0, 0] + 0.002
        M = F + noise * rng.standard_normal(F.shape)
        parts.append((wl, M, F, noise))
    cat = lambda f: np.concatenate([f(*p) for p in parts])
    values = {e: cat(lambda wl, M, F, s, e=e: M[int(e[1]), int(e[2])] / M[0, 0]) for e in ELEMENTS}
    sigma = {e: cat(lambda wl, M, F, s, e=e: s * np.hypot(1, F[int(e[1]), int(e[2])] / F[0, 0]) / F[0, 0])
             for e in ELEMENTS}
    return Measurements(np.tile(ti, 2), np.tile(tr, 2), np.tile(ph, 2), values, sigma=sigma,
                        m00=cat(lambda wl, M, F, s: M[0, 0]) if with_m00 else None,
                        m00_sigma=cat(lambda wl, M, F, s: s) if with_m00 else None,
                        wavelength_nm=cat(lambda wl, M, F, s: np.full(n, wl)))


@pytest.mark.parametrize("shadowing", ["vgroove", "smith", "none"])
@pytest.mark.parametrize("diffuse", ["paper", "reciprocal", "none", "lambertian"])
def test_prepared_factors_equal_pbrdf(shadowing, diffuse):
    """lobe(s) x U(n, k) + diffuse(s) U_00 (+ the Lambertian albedo / pi) is Eq. 17 itself: all 16
    elements to 1e-13 relative."""
    if shadowing == "none" and diffuse == "reciprocal":
        pytest.skip("undefined pair")
    ti, tr, ph = geometry(200)
    albedo = 0.07 if diffuse == "lambertian" else None
    F = pbrdf(ti, tr, ph, rms_slope=0.25, n=1.4, k=4.2, shadowing=shadowing, diffuse=diffuse,
              diffuse_reflectance=albedo)
    G = np.moveaxis(PreparedGeometry(ti, tr, ph).mueller(0.25, 1.4, 4.2, shadowing, diffuse, albedo), (0, 1), (-2, -1))
    assert np.abs(F - G).max() <= 1e-13 * np.abs(F).max()


# ---------------------------------------------------------------------------- the CSV

HEAD = "wavelength_nm,theta_i_deg,theta_r_deg,phi_i_deg,phi_r_deg,M00,M00_sigma,M22,M22_sigma\n"


def test_csv_reads_m00_wavelengths_and_goniometer_azimuths(tmp_path):
    """M00 (1/sr), a wavelength per row and the goniometer's two azimuths (phi = phi_r - phi_i mod 360)."""
    p = tmp_path / "lab.csv"
    p.write_text(HEAD + "632.8,30,30,0,180,2.31,0.025,-0.81,0.012\n1550,30,45,10,-120,0.58,0.008,-0.32,0.02\n")
    m = read_measurements(p)
    np.testing.assert_allclose(np.degrees(m.phi), [180.0, 230.0])
    np.testing.assert_allclose(m.m00, [2.31, 0.58])
    assert m.wavelengths == (632.8, 1550.0)
    back = read_measurements(write_measurements(tmp_path / "back.csv", m))
    np.testing.assert_allclose(back.m00_uncertainty(), [0.025, 0.008])
    np.testing.assert_allclose(np.degrees(back.phi), [180.0, 230.0])


def test_values_outside_the_physical_range_are_judged_by_their_sigma(tmp_path):
    """The issue's row: M22 = -1.68 +- 0.65 lies within 3 sigma of -1 and is data; -1.68 +- 0.1 is
    6.8 sigma beyond it, impossible, refused naming the line; M00 likewise against 0."""
    ok = tmp_path / "ok.csv"
    ok.write_text(HEAD + "632.8,30,30,0,180,2.31,0.025,-1.68,0.65\n632.8,30,40,0,180,-0.05,0.025,-0.5,0.1\n")
    m = read_measurements(ok)
    assert m.values["M22"][0] == -1.68 and m.m00[1] == -0.05
    bad = tmp_path / "bad.csv"
    bad.write_text("# a comment\n" + HEAD + "632.8,30,30,0,180,2.31,0.025,-0.5,0.1\n632.8,30,30,0,180,2.3,0.02,-1.68,0.1\n")
    with pytest.raises(MeasurementFileError, match=r"bad.csv, line 4, column 'M22': -1.68 is not a normalized element.*"
                                                    r"6.8 standard deviations"):
        read_measurements(bad)


# ---------------------------------------------------------------------------- the joint fit

@pytest.fixture(scope="module")
def lab_fit():
    return fit_lab(lab_measurements(), shadowing="smith", diffuse="lambertian")


def test_joint_fit_recovers_roughness_index_and_albedo(lab_fit):
    """With M00: one roughness, n and k at each wavelength, the albedo, each within 4 standard errors
    of the generating value, and the model adequate."""
    r = lab_fit
    assert r.verdict.adequate and r.success
    values = {(p["name"], p["wavelength_nm"]): (p["value"], p["stderr"]) for p in r.parameters()}
    truth = {("rms_slope", None): TRUTH["rms_slope"], ("diffuse_reflectance", None): TRUTH["albedo"]}
    truth.update({(q, wl): TRUTH[wl][i] for wl in (632.8, 1550.0) for i, q in enumerate(("n", "k"))})
    for key, t in truth.items():
        v, e = values[key]
        assert abs(v - t) < 4 * e, (key, v, e, t)
    assert values[("rms_slope", None)][1] < 0.01 * TRUTH["rms_slope"]


def test_json_result_has_the_issue_schema(lab_fit, tmp_path, capsys):
    """The dict's keys, one entry per parameter and wavelength, covariance names matching the fitted
    ones, strict JSON (no NaN); the command line writes the same dict."""
    d = lab_fit.to_dict()
    assert set(d) == {"model", "parameters", "covariance", "verdict", "models"}
    assert d["model"] == {"shadowing": "smith", "diffuse": "lambertian"}
    assert all(set(p) == {"name", "wavelength_nm", "value", "stderr"} for p in d["parameters"])
    assert [(p["name"], p["wavelength_nm"]) for p in d["parameters"]] == [
        ("n", 632.8), ("n", 1550.0), ("k", 632.8), ("k", 1550.0), ("rms_slope", None), ("diffuse_reflectance", None)]
    assert d["covariance"]["names"] == ["n@632.8nm", "k@632.8nm", "n@1550nm", "k@1550nm", "rms_slope",
                                        "diffuse_reflectance"]
    assert np.shape(d["covariance"]["matrix"]) == (6, 6)
    assert set(d["verdict"]) == {"adequate", "chi2_reduced", "p_value", "warnings"}
    json.dumps(d, allow_nan=False)
    csv = write_measurements(tmp_path / "lab.csv", lab_measurements())
    out = tmp_path / "fit.json"
    assert main(["fit", str(csv), "--shadowing", "smith", "--diffuse", "lambertian", "--json", str(out), "-q"]) == 0
    xml = capsys.readouterr().out      # measured at 632.8 and 1550 nm: held from 360 nm up, said so
    assert '<spectrum name="eta" value="360:' in xml and "over 360-632.8 nm the end values are held" in xml
    cli = json.loads(out.read_text())
    assert cli["model"] == d["model"]
    for a, b in zip(cli["parameters"], d["parameters"]):
        assert a["name"] == b["name"] and a["value"] == pytest.approx(b["value"], rel=1e-6)


def test_a_misfit_from_a_fixed_roughness_is_blamed_on_it_not_on_the_sigmas():
    """The issue's CSV default held rms_slope at 0.3 and blamed the sigmas; now the verdict names the
    fixed parameter and what freeing it gives."""
    with pytest.warns(UserWarning):
        r = fit_lab(lab_measurements(), fit="n,k,diffuse_reflectance", rms_slope=0.3, shadowing="smith",
                    diffuse="lambertian")
    assert not r.verdict.adequate
    assert "held fixed (rms_slope = 0.3) cause the misfit, not the sigmas" in r.verdict.message
    assert "underestimate" not in r.verdict.message
    assert r.blamed.values[("rms_slope", None)] == pytest.approx(TRUTH["rms_slope"], rel=0.02)


def test_without_m00_the_roughness_is_reported_as_seen_through_the_diffuse_term():
    """Normalized elements only: with a Lambertian term rms_slope is fitted and the warning says it is
    determined only through the diffuse term; without a diffuse term it is not fitted at all."""
    m = lab_measurements(with_m00=False)
    r = fit_lab(m, shadowing="smith", diffuse="lambertian")
    assert any("determined only through the diffuse term (lambertian)" in w for w in r.warnings + r.notes)
    assert any("determined only through the diffuse term" in w for w in r.to_dict()["verdict"]["warnings"])
    assert ("rms_slope", None) in r.fit.free
    with pytest.warns(UserWarning):
        bare = fit_lab(m, shadowing="smith", diffuse="none")
    assert ("rms_slope", None) not in bare.fit.free
    assert any("rms_slope is not identified" in w for w in bare.warnings)


# ---------------------------------------------------------------------------- a fit's material exported

def test_export_takes_a_fits_index_per_wavelength_and_refuses_outside_it(tmp_path, capsys):
    """``hyde-bsdf export --fit FIT.json``: the index interpolated between the measured wavelengths; a
    band outside them (all of 450-650 nm but none here: the fit spans 400-700 nm) is refused unless
    --extrapolate, which warns; a fit at one wavelength is refused at every band."""
    from hyde_bsdf.fit.lab import material_at

    fit = {"model": {"shadowing": "smith", "diffuse": "lambertian"},
           "parameters": [{"name": "n", "wavelength_nm": 400.0, "value": 1.0, "stderr": 0.1},
                          {"name": "n", "wavelength_nm": 700.0, "value": 0.4, "stderr": 0.1},
                          {"name": "k", "wavelength_nm": 400.0, "value": 2.0, "stderr": 0.1},
                          {"name": "k", "wavelength_nm": 700.0, "value": 4.0, "stderr": 0.1},
                          {"name": "rms_slope", "wavelength_nm": None, "value": 0.25, "stderr": 0.01},
                          {"name": "diffuse_reflectance", "wavelength_nm": None, "value": 0.1, "stderr": 0.01}]}
    m = material_at(fit, [550.0])
    assert m["n"] == pytest.approx([0.7]) and m["k"] == pytest.approx([3.0]) and not m["extrapolated"]
    path = tmp_path / "fit.json"
    path.write_text(json.dumps(fit))
    out = tmp_path / "m.pbsdf"
    assert main(["export", str(out), "--fit", str(path), "--resolution", "4x4x4", "--error-samples", "0", "-q"]) == 0
    assert "diffuse_reflectance = 0.1" in capsys.readouterr().out
    one = dict(fit, parameters=[p for p in fit["parameters"] if p["wavelength_nm"] != 700.0])
    path.write_text(json.dumps(one))
    assert main(["export", str(out), "--fit", str(path), "--resolution", "4x4x4", "--error-samples", "0", "-q"]) == 2
    assert "the fit was measured at 400 nm; the export needs" in capsys.readouterr().err
    assert main(["export", str(out), "--fit", str(path), "--extrapolate", "--resolution", "4x4x4",
                 "--error-samples", "0", "-q"]) == 0
    assert "the nearest measured index is held" in capsys.readouterr().err
    # a Lambertian term's albedo is never a silent default (0.5 was written before)
    plain = ["export", str(out), "--rms-slope", "0.25", "--material", "Au", "--diffuse", "lambertian",
             "--resolution", "4x4x4", "--error-samples", "0", "-q"]
    assert main(plain) == 2
    assert "diffuse_reflectance must be given with diffuse='lambertian'" in capsys.readouterr().err
    assert main(plain + ["--diffuse-reflectance", "0.1"]) == 0
    assert "diffuse_reflectance = 0.1" in capsys.readouterr().out


def test_the_one_wavelength_fit_refuses_what_it_would_drop():
    """fit_measurements (fit_mueller on Measurements) fits one index to normalized elements: given
    M00 or two wavelengths it would drop M00 and mix the wavelengths silently, so it refuses and
    names fit_lab.  < 1 s."""
    from hyde_bsdf.errors import UsageError
    from hyde_bsdf.fit.mueller_fit import fit_measurements

    with pytest.raises(UsageError, match="2 wavelengths and M00 in 1/sr.*fit_lab"):
        fit_measurements(lab_measurements())
    with pytest.raises(UsageError, match="have 2 wavelengths; .*fit_lab"):
        fit_measurements(lab_measurements(with_m00=False))


def test_normalized_rows_are_whitened_with_their_shared_m00_noise():
    """Without M00 a row's ratios M_jk/M00 share M00's noise: covariance C = diag(own^2) + s s^T per
    row (s = delta r, own^2 = sigma^2 - s^2).  ``LabData.whiten`` (Sherman-Morrison, one dot product
    per row) gives e^T C^-1 e, the chi^2 of the dense covariance, to 1e-10 relative, and whitens
    Jacobian columns the same way; rows whose sigmas imply M00 is not above 0 within 3 sigma are left
    out and counted.  < 1 s."""
    from hyde_bsdf.fit.lab_data import RATIO_DELTA, lab_data

    meas = lab_measurements(with_m00=False, n=40)
    data = lab_data(meas)
    data = data.with_shared(data.y * (1.0 + 0.1 * np.sin(np.arange(data.y.size))))   # a model's r, not the data's
    C, N = len(data.columns), data.geometries
    own2 = np.maximum(data.w ** 2 - data.shared ** 2, (0.1 * data.w) ** 2).reshape(C, N)
    s = data.shared.reshape(C, N)
    e = np.random.default_rng(3).standard_normal(data.y.size) * data.w
    E = e.reshape(C, N)
    dense = sum(E[:, i] @ np.linalg.solve(np.diag(own2[:, i]) + np.outer(s[:, i], s[:, i]), E[:, i])
                for i in range(N))
    assert float(data.whiten(e) @ data.whiten(e)) == pytest.approx(dense, rel=1e-10)
    J = np.stack([e, 2 * e], axis=1)
    assert np.allclose(data.whiten(J), np.stack([data.whiten(e), 2 * data.whiten(e)], axis=1), rtol=1e-12)
    # a row whose M00 is noise (every sigma large): left out, counted, named in the fit's notes
    noisy = lab_measurements(with_m00=False, n=40)
    for e_ in noisy.sigma:
        noisy.sigma[e_][:3] = 2 * RATIO_DELTA * np.hypot(1.0, noisy.values[e_][:3])
    kept = lab_data(noisy)
    assert kept.groups[0].uninformative == 3 and kept.groups[0].rows_in == 40


def test_index_spectra_are_held_over_mitsubas_colour_range_and_say_so():
    """An index measured at 450-650 nm, written as it was measured, is 0 outside in spectral variants
    and the wrong colour in RGB ones (Mitsuba integrates the spectrum over 360-830 nm: a constant 0.5
    becomes the RGB index (0.42, 0.53, 0.25)).  spectrum_element holds the end values out to 360 and
    830 nm, so the RGB index of a flat measurement is that value to 0.2 %, and the note says where it
    extrapolates.  < 1 s."""
    from hyde_bsdf.fit.spectral import extrapolation_warning, spectrum_element
    from hyde_bsdf.mitsuba.variants import set_variant
    import mitsuba as mi

    wl = [450.0, 550.0, 650.0]
    xml = spectrum_element("eta", wl, [0.5, 0.5000001, 0.5])
    assert xml.startswith('<spectrum name="eta" value="360:0.5, 450:0.5') and xml.endswith('650:0.5, 830:0.5"/>')
    set_variant("scalar_rgb", fallback=False)
    params = mi.traverse(mi.load_string(f'<bsdf version="3.0.0" type="roughconductor">{xml}</bsdf>'))
    assert np.allclose(np.asarray(params["eta.value"]), 0.5, rtol=2e-3)
    assert "over 360-450 and 650-830 nm the end values are held" in extrapolation_warning(wl)
    assert extrapolation_warning([300.0, 900.0]) is None
