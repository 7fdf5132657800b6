"""Energy of the ``hyde`` plugin in a white furnace (issue 31): its default material, the paper's
Eq. 17 term, the sampling density, and the warning of shadowing="none".

Physics checked, with the lossless index n + ik = i (|r_s| = |r_p| = 1, so M00 = 1 and the albedo is
that of the model's geometry), ``llvm_ad_rgb``, NumPy's seeded generator for the random numbers:

- the default material (V-groove + the reciprocal diffuse term) returns at most the light it receives,
  in radiance and in importance mode, at grazing cells where the paper's term gains the most
  (albedo <= 1 + 3 standard errors + 2e-4, the DHR table's interpolation bound; 2^18 samples per
  cell, sampling weights and MIS of eval/pdf);
- the paper's Eq. 17 term, still available by name, gains in radiance mode exactly as its closed form
  says (rho^s(theta) + 1 - rho_avg from the DHR table, within 4 standard errors) and conserves
  energy in importance mode;
- the sampling weight of the V-groove lobe is unbiased: its mean equals the integral of ``eval``
  (Gauss-Legendre quadrature, 600 x 1200 nodes) within 4 standard errors at theta 75 deg,
  rms_slope 0.385, where a density written with Mitsuba's rational Smith G1 (the visible-normal
  sampler draws from the exact one) is 0.28 % off (14 standard errors);
- shadowing="none" warns once, at load or at the update that makes its albedo exceed 1.

Cost: ~10 s (kernel compilation of three models, 2^18-sample cells).
"""
import math
import warnings

import numpy as np
import pytest

from hyde_bsdf.validation import furnace

SAMPLES = 1 << 18


@pytest.fixture(scope="module")
def mi():
    import mitsuba as mi

    import hyde_bsdf

    mi.set_variant(furnace.VARIANT)
    hyde_bsdf.register(furnace.VARIANT)
    return mi


def _albedo(mi, bsdf, mode, theta_deg, samples=SAMPLES, seed=3):
    import drjit as dr

    return furnace._estimates(mi, dr, bsdf, mode, np.radians(np.atleast_1d(theta_deg)), samples, seed)


def _pec(mi, **kw):
    return mi.load_dict({"type": "hyde", "eta": 0.0, "k": 1.0, **kw})


def test_the_default_material_is_vgroove_reciprocal_and_returns_no_more_than_it_receives(mi):
    """Cells where the paper's term gains most (89.5 deg at rms_slope 9.9: 1.93; 85 deg at 1.0: 1.44)."""
    bsdf = _pec(mi)
    assert (bsdf.m_shadowing, bsdf.m_diffuse) == ("vgroove", "reciprocal")
    params = mi.traverse(bsdf)
    for rms, theta in ((9.87, 89.5), (1.0, 85.0), (0.385, 75.0), (0.05, 88.0)):
        params["rms_slope.value"] = rms
        params.update()
        for mode in furnace.MODES:
            est = _albedo(mi, bsdf, mode, theta)
            z = furnace.excess(est[:, 0], est[:, 1])
            assert np.all(z <= 3.0), (rms, theta, mode, est[:, :, 0])


def test_the_papers_term_gains_in_radiance_mode_as_its_closed_form_says(mi):
    """Eq. 17 in a path tracer: rho^s(theta) + 1 - rho_avg (above 1 at grazing), importance mode 1."""
    from hyde_bsdf.model.dhr import load_table

    table = load_table("vgroove")
    bsdf = _pec(mi, rms_slope=1.0, diffuse="paper")
    theta = 85.0
    rad, imp = _albedo(mi, bsdf, "radiance", theta), _albedo(mi, bsdf, "importance", theta)
    predicted = float(table(math.radians(theta), 1.0)) + 1.0 - float(table.average(1.0))
    assert predicted > 1.4
    assert np.all(np.abs(rad[:, 0, 0] - predicted) <= 4 * rad[:, 1, 0] + 2e-4), (rad[:, :, 0], predicted)
    assert np.all(np.abs(imp[:, 0, 0] - 1.0) <= 4 * imp[:, 1, 0] + 2e-4), imp[:, :, 0]


def test_vgroove_sampling_weight_is_unbiased(mi):
    """Mean sampling weight = the integral of eval (quadrature) at the cell of Mitsuba's G1 fit's largest
    bias: the visible-normal density must be the exact Smith G1's."""
    import drjit as dr

    theta, rms = 75.0, 0.385
    bsdf = _pec(mi, rms_slope=rms, diffuse="none")
    x, w = np.polynomial.legendre.leggauss(600)
    mu, wm = 0.5 * (x + 1.0), 0.5 * w
    nphi = 1200
    phi = (np.arange(nphi) + 0.5) * 2.0 * math.pi / nphi
    MU, PH = np.meshgrid(mu, phi, indexing="ij")
    s = np.sqrt(1.0 - MU * MU)
    si = dr.zeros(mi.SurfaceInteraction3f, MU.size)
    si.wi = mi.Vector3f(math.sin(math.radians(theta)), 0.0, math.cos(math.radians(theta)))
    si.n = mi.Normal3f(0, 0, 1)
    si.sh_frame = mi.Frame3f(si.n)
    wo = mi.Vector3f(*(np.ravel(a).astype(np.float32) for a in (s * np.cos(PH), s * np.sin(PH), MU)))
    f = np.asarray(bsdf.eval(mi.BSDFContext(), si, wo)[0], dtype=float).reshape(MU.shape)
    integral = float(np.sum(f * wm[:, None]) * 2.0 * math.pi / nphi)
    est = _albedo(mi, bsdf, "radiance", theta, samples=1 << 21)
    assert abs(est[0, 0, 0] - integral) <= 4 * est[0, 1, 0], (est[0, :, 0], integral)


def test_shadowing_none_warns_once_when_its_albedo_can_exceed_one(mi):
    def load(**kw):
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            bsdf = _pec(mi, shadowing="none", diffuse="none", **kw)
        return bsdf, [str(c.message) for c in caught if "reflects more light" in str(c.message)]

    bsdf, said = load(rms_slope=0.3)
    assert len(said) == 1 and "exceeds 1 from 71.5 deg on" in said[0] and "14.2 at 89.5 deg" in said[0], said
    quiet, said = load(rms_slope=1e-3)        # rho(89.5 deg) = 0.99999: no gain within the furnace's angles
    assert said == []
    params = mi.traverse(quiet)
    for value in (0.5, 1.0):                  # the update that brings a gain warns, once
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            params["rms_slope.value"] = value
            params.update()
        said = [str(c.message) for c in caught if "reflects more light" in str(c.message)]
        assert len(said) == (1 if value == 0.5 else 0), said
