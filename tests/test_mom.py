"""Tests of the method-of-moments reference solver (hyde_bsdf.mom, paper Eqs. 18-23).

Physics checked: the Gaussian surface generator has the requested height and slope
statistics; a flat PEC plate reflects all power coherently into the specular
direction with the physical-optics peak; a small rough PEC surface conserves
power (no absorption); the same seed gives the same answer in any executor;
and the solver says so when MoM itself cannot be trusted.
"""
from __future__ import annotations

import math
import warnings

import numpy as np
import pytest

from hyde_bsdf import mom

SERIAL = mom.SerialExecutor()


def test_surface_statistics_and_resampling():
    """Fung-Chen surface: rms height sigma_h, rms slope sqrt(2) sigma_h/ell, correlation exp(-1) at lag ell."""
    sigma_h, ell = 0.5, 2.0
    x, f, s = mom.gaussian_surface(4000.0, 40000, sigma_h, ell, seed=3)
    # 4000 lambda / 2 lambda = 2000 correlation lengths: sampling error of the rms ~ 1/sqrt(2000) ~ 2 %
    assert f.std() == pytest.approx(sigma_h, rel=0.05)
    assert s.std() == pytest.approx(math.sqrt(2) * sigma_h / ell, rel=0.05)
    lag = 20  # = ell / dx
    rho = np.mean(f[:-lag] * f[lag:]) / np.mean(f * f)
    assert rho == pytest.approx(math.exp(-1), abs=0.05)
    # the slope is the derivative of the heights (centred difference, error O(dx^2/ell^2))
    np.testing.assert_allclose(np.gradient(f, x)[1:-1], s[1:-1], atol=5e-3)
    # same seed, other sampling: the same band-limited surface
    x2, f2, _ = mom.gaussian_surface(4000.0, 16000, sigma_h, ell, seed=3)
    np.testing.assert_allclose(f2, np.interp(x2, x, f), atol=2e-3)


@pytest.mark.parametrize("theta_i", [0.0, 30.0, 60.0])
def test_flat_plate_specular_only(theta_i):
    """Flat PEC plate: all reflected power is coherent, in the specular spike, power balance 1.

    Two identical partitions make the incoherent part vanish exactly.  The peak
    follows from the physical-optics current Z0 J = 2 cos(ti) e^{-jkx sin ti}
    under the taper: F = 2 cos(ti) w sqrt(pi), sigma = (pi/2)|F|^2/(w sqrt(pi/2)).
    """
    w = 60.0 / 4
    res = mom.scatter(120.0, 2, 0.0, 1.0, theta_i, [theta_i, theta_i + 10.0, -theta_i - 5.0],
                      pts_per_wl=10, executor=SERIAL)
    assert res.power_balance[0] == pytest.approx(1.0, abs=0.01)
    assert res.power_balance_nominal[0] == pytest.approx(1.0, abs=0.01)
    assert res.power_coherent[0] == pytest.approx(res.power_balance_nominal[0], rel=1e-9)
    peak_po = (math.pi / 2) * (2 * math.cos(math.radians(theta_i)) * w * math.sqrt(math.pi)) ** 2 \
        / (w * math.sqrt(math.pi / 2))
    assert res.sigma[0, 0] == pytest.approx(peak_po, rel=0.02)
    # away from the spike (10 deg is > 20 spike widths) almost nothing
    assert np.all(res.sigma[0, 1:] < 1e-3 * res.sigma[0, 0])
    np.testing.assert_allclose(res.sigma_incoherent, 0.0, atol=1e-9 * res.sigma[0, 0])


def test_small_rough_surface_conserves_power():
    """Rough PEC (rms slope 0.3, k sigma_h = 1.9), 4 partitions of 75 lambda: power balance within 1.5 % of 1.

    The power balance of a finite sample fluctuates: a tapered partition whose ends
    differ in height is tilted, and intercepts cos(ti + tilt)/cos(ti) of the nominal
    power; the tilt ~ sqrt(2) sigma_h / (w sqrt(pi/2)) averages out only as 1/sqrt(M).
    At theta_i <= 40 deg this is < 1 % here; the full Fig. 6 case (100 partitions of
    150 lambda) is checked to 1 % up to 75 deg by hyde_bsdf/validation/fig6_mom.py.
    """
    sigma_h = 0.3
    ell = math.sqrt(2) * sigma_h / 0.3  # rms slope 0.3, as in Fig. 6
    res = mom.scatter(300.0, 4, sigma_h, ell, [0.0, 20.0, 40.0], np.arange(-90, 91, 2.0),
                      pts_per_wl=8, seed=1, executor=SERIAL)
    np.testing.assert_allclose(res.power_balance, 1.0, atol=0.015)
    # k sigma_h = 1.9: the coherent (specular) share exp(-(2 k sigma_h cos ti)^2) ~ 1e-6 is lost in the
    # estimate's noise (~ incoherent / sqrt(M))
    assert np.all(np.abs(res.power_coherent) < 0.15)
    assert np.all(np.isfinite(res.sigma)) and np.all(res.sigma >= 0)


def test_reproducible_by_seed_and_executor():
    """Same seed: the same sigma, serially, in the default process pool or any other Executor;
    another seed: another surface."""
    from concurrent.futures import ThreadPoolExecutor

    args = (60.0, 2, 0.3, 1.5, [20.0], np.arange(-80, 81, 10.0))
    a = mom.scatter(*args, pts_per_wl=6, seed=7, executor=SERIAL)
    b = mom.scatter(*args, pts_per_wl=6, seed=7)  # default process pool
    with ThreadPoolExecutor(2) as pool:
        t = mom.scatter(*args, pts_per_wl=6, seed=7, executor=pool)
    c = mom.scatter(*args, pts_per_wl=6, seed=8, executor=SERIAL)
    np.testing.assert_allclose(a.sigma, b.sigma, rtol=1e-10)
    np.testing.assert_allclose(a.sigma, t.sigma, rtol=1e-10)
    np.testing.assert_allclose(a.power_balance, b.power_balance, rtol=1e-12)
    assert np.max(np.abs(a.sigma - c.sigma)) > 1e-2 * np.max(a.sigma)


def test_warns_when_mom_fails():
    """Too few points per wavelength, a taper too narrow for grazing incidence, partitions too short."""
    with pytest.warns(mom.MoMAccuracyWarning, match="points per wavelength"):
        mom.scatter(20.0, 1, 0.0, 1.0, 0.0, 0.0, pts_per_wl=4, executor=SERIAL)
    with pytest.warns(mom.MoMAccuracyWarning, match=r"taper too narrow .* estimated power error of s [-+]"):
        res = mom.scatter(40.0, 1, 0.0, 1.0, 80.0, 80.0, pts_per_wl=6, executor=SERIAL, incidence="window")
    assert abs(res.power_balance[0] - 1.0) > 0.05  # and indeed the power balance is off
    with pytest.warns(mom.MoMAccuracyWarning, match="shorter than 10 correlation"):
        mom.scatter(40.0, 2, 1.0, 4.0, 0.0, 0.0, pts_per_wl=6, executor=SERIAL)
    with warnings.catch_warnings():
        warnings.simplefilter("error", mom.MoMAccuracyWarning)  # a sound set-up stays silent
        mom.scatter(40.0, 1, 0.0, 1.0, 30.0, 30.0, pts_per_wl=6, executor=SERIAL)


@pytest.mark.parametrize("kwargs, name", [
    ({"pts_per_wl": 1.5}, "pts_per_wl"),
    ({"theta_i_deg": 90.0}, "theta_i_deg"),
    ({"theta_r_deg": [0.0, 95.0]}, "theta_r_deg"),
    ({"partitions": 0}, "partitions"),
    ({"rms_height_wl": -0.1}, "rms_height_wl"),
    ({"corr_length_wl": float("nan")}, "corr_length_wl"),
    ({"rms_height_wl": 0.1, "corr_length_wl": 0.5, "pts_per_wl": 3.0}, "pts_per_wl"),
])
def test_bad_input_names_parameter(kwargs, name):
    args = {"length_wl": 20.0, "partitions": 1, "rms_height_wl": 0.0, "corr_length_wl": 1.0,
            "theta_i_deg": 0.0, "theta_r_deg": 0.0, "executor": SERIAL}
    args.update(kwargs)
    with pytest.raises(ValueError, match=name), warnings.catch_warnings():
        warnings.simplefilter("ignore", mom.MoMAccuracyWarning)  # coarse sampling also warns before it fails
        mom.scatter(**args)


# --- the pBRDF's 1-D reduction (hyde_bsdf.mom.model1d), the MoM's apples-to-apples counterpart ---

def test_model1d_conserves_energy_and_is_reciprocal():
    """1-D Eqs. 14-17 for a PEC: specular + Lambertian diffuse reflect exactly all power;
    the specular term is reciprocal, f_s(ti -> tr) = f_s(tr -> ti) (mirror the geometry: tr -> -tr)."""
    from hyde_bsdf.mom import model1d

    ti = np.radians([0.0, 10.0, 30.0, 45.0, 60.0, 75.0])
    tr = np.linspace(-math.pi / 2, math.pi / 2, 4001)
    sigma = model1d.sigma_equivalent(ti[:, None], tr, 0.3)
    power = np.trapezoid(sigma, tr, axis=1) / (2 * math.pi * np.cos(ti))
    np.testing.assert_allclose(power, 1.0, atol=1e-4)
    rho = model1d.dhr_specular(ti, 0.3)
    assert np.all((rho > 0.9) & (rho < 1.0))  # shadowing removes a few percent at rms slope 0.3
    a, b = np.radians(20.0), np.radians(55.0)
    # source at -a, observer at +b  <->  source at -b, observer at +a (same facet tilt magnitude)
    assert model1d.brdf_specular(a, b, 0.3) == pytest.approx(model1d.brdf_specular(b, a, 0.3), rel=1e-12)
    assert np.isfinite(model1d.brdf(0.0, math.pi / 2, 0.3))


def test_model1d_unshadowed_projected_area_identity():
    """Without shadowing and over all facet tilts, the facets' projected length is the mean surface's:
    int p(alpha) cos(ti + alpha) / (cos alpha cos ti) d alpha = 1 - tan(ti) <tan alpha> = 1."""
    from hyde_bsdf.mom import model1d

    alpha = np.linspace(-math.pi / 2 + 1e-6, math.pi / 2 - 1e-6, 200001)
    p = model1d.facet_pdf(alpha, 0.3)
    assert np.trapezoid(p, alpha) == pytest.approx(1.0, abs=1e-8)
    ti = math.radians(50.0)
    proj = np.trapezoid(p * np.cos(ti + alpha) / (np.cos(alpha) * math.cos(ti)), alpha)
    assert proj == pytest.approx(1.0, abs=1e-8)


def test_mom_lobe_matches_the_1d_facet_model():
    """High-frequency limit: on a geometrical-optics surface (k ell = 25, k sigma_h = 5.3) the MoM's
    scattering lobe has the centroid and width of the pBRDF's 1-D reduction, including the shift of
    the lobe below the specular angle that the 1-D facet geometry (cos beta) predicts.

    20 partitions of 60 lambda leave sampling noise: over seeds 0-3 the centroids scatter by
    +-2.5 deg and the widths by +-3 deg around the model, hence the 4-degree tolerances.
    """
    from hyde_bsdf.mom import model1d

    ell = 4.0
    res = mom.scatter(1200.0, 20, 0.3 * ell / math.sqrt(2), ell, [20.0, 50.0], [0.0], pts_per_wl=8, seed=0,
                      executor=SERIAL, progress=False)
    tr = res.fine_theta_r

    def centroid_width(s):
        p = np.trapezoid(s, tr, axis=1)
        c = np.trapezoid(s * tr, tr, axis=1) / p
        return np.degrees(c), np.degrees(np.sqrt(np.trapezoid(s * (tr - c[:, None]) ** 2, tr, axis=1) / p))

    c_mom, w_mom = centroid_width(res.fine_sigma)
    c_mod, _ = centroid_width(model1d.sigma_equivalent(res.theta_i[:, None], tr, 0.3))
    _, w_spec = centroid_width(model1d.sigma_equivalent(res.theta_i[:, None], tr, 0.3, diffuse=False))
    np.testing.assert_allclose(c_mom, c_mod, atol=4.0)
    np.testing.assert_allclose(w_mom, w_spec, atol=4.0)
    assert np.all(np.array([20.0, 50.0]) - c_mom > 4.0)  # the lobe sits below the specular angle


def test_progress_goes_through_a_callback(monkeypatch, capsys):
    """scatter(progress=callable) reports 'partition done/total, elapsed, left' through the callback (throttle cut to
    0 s here), one line per partition, on stdout/stderr nothing."""
    from hyde_bsdf import progress

    monkeypatch.setattr(mom.solver, "Throttle", lambda cb: progress.Throttle(cb, seconds=0.0))
    lines = []
    mom.scatter(20.0, 3, 0.0, 1.0, 0.0, 0.0, pts_per_wl=6, executor=SERIAL, progress=lines.append)
    assert [line.split(",")[0] for line in lines] == ["partition 1/3", "partition 2/3", "partition 3/3"]
    assert lines[-1].endswith("~0 s left")
    assert capsys.readouterr() == ("", "")
