"""Tests of the two-polarisation, finite-index MoM (hyde_bsdf.mom.scatter with polarization= and n=, k=).

Physics checked: a flat plate of a metal or of glass reflects the Fresnel |r_s|^2,
|r_p|^2 with the Fresnel phase arg(r_p / r_s), and what it does not reflect flows into
it (Poynting on the surface fields); a PEC mirror's Mueller matrix is diag(1, 1, -1, -1);
rough PEC and metal surfaces conserve energy in both polarisations; both polarisations
see the same surface; the 1-D model's Mueller elements reduce to Fresnel.  And the
MoM refuses or warns where it cannot be trusted (issue 10): steep surfaces, a bad seed,
a taper wider than its partition, too few points per interior wavelength, a solve that
does not conserve energy.
"""
from __future__ import annotations

import gc
import math
import warnings

import numpy as np
import pytest

from hyde_bsdf import mom
from hyde_bsdf.mom import model1d, runtime
from hyde_bsdf.model.fresnel import fresnel_rs_rp

SERIAL = mom.SerialExecutor()
INFRAGOLD = (0.285, 7.3523)   # the paper's eta = n - j kappa at 10.6 um
GLASS = (1.5, 0.0)


@pytest.mark.parametrize("nk", [INFRAGOLD, GLASS], ids=["infragold", "glass"])
def test_flat_plate_reproduces_fresnel(nk):
    """60-lambda tapered plate, 10 pts/lambda: reflectance within 0.005 of Fresnel, phase of r_p/r_s
    within 0.4 deg (glass at 60 deg is 4 deg from Brewster, |r_p|^2 = 0.002), reflected + absorbed = 1
    within 0.5 %.  (hyde_bsdf/validation/mom_polarization.py checks 0-80 deg on longer plates.)"""
    n, k = nk
    ti = np.array([0.0, 40.0, 60.0])
    res = mom.scatter(60.0, 1, 0.0, 1.0, ti, ti, pts_per_wl=10, executor=SERIAL, polarization=("s", "p"),
                      n=n, k=k)
    rs, rp = fresnel_rs_rp(np.cos(np.radians(ti)), n, k)
    np.testing.assert_allclose(res.power_balance_s, np.abs(rs) ** 2, atol=0.005)
    np.testing.assert_allclose(res.power_balance_p, np.abs(rp) ** 2, atol=0.005)
    np.testing.assert_allclose(res.energy_s, 1.0, atol=0.005)
    np.testing.assert_allclose(res.energy_p, 1.0, atol=0.005)
    np.testing.assert_allclose(res.absorbed_s, 1.0 - np.abs(rs) ** 2, atol=0.005)
    # sigma_sp = <F_s F_p*> ~ r_s r_p*, so sigma_sp * (r_p / r_s) ~ |r_p|^2 has phase 0
    phase = np.degrees(np.angle(np.diag(res.sigma_sp) * (rp / rs)))
    np.testing.assert_allclose(phase, 0.0, atol=0.4)


def test_pec_mirror_mueller_and_same_surface():
    """Flat PEC: at specular M01/M00 = 0, M22/M00 = -1, M23/M00 = 0 (the mirror diag(1, 1, -1, -1)),
    p conserves power; and the s result of a two-polarisation run is the s-only run's (to round-off: the
    far field of both polarisations is summed in one matrix product)."""
    both = mom.scatter(60.0, 2, 0.0, 1.0, [20.0, 50.0], [20.0, 50.0], pts_per_wl=10, executor=SERIAL,
                       polarization=("s", "p"))
    mn = both.mueller_normalised
    spec = (np.arange(2), np.arange(2))
    np.testing.assert_allclose(mn["M01/M00"][spec], 0.0, atol=0.01)
    np.testing.assert_allclose(mn["M22/M00"][spec], -1.0, atol=0.01)
    np.testing.assert_allclose(mn["M23/M00"][spec], 0.0, atol=0.01)
    np.testing.assert_allclose(both.power_balance_p, 1.0, atol=0.005)
    np.testing.assert_allclose(both.absorbed_p, 0.0, atol=0.0)
    s_only = mom.scatter(60.0, 2, 0.0, 1.0, [20.0, 50.0], [20.0, 50.0], pts_per_wl=10, executor=SERIAL)
    np.testing.assert_allclose(both.sigma_s, s_only.sigma, rtol=1e-10, atol=1e-12 * both.sigma_s.max())
    np.testing.assert_allclose(both.sigma, s_only.sigma, rtol=1e-10, atol=1e-12 * both.sigma_s.max())


@pytest.mark.parametrize("nk", [None, INFRAGOLD], ids=["pec", "infragold"])
def test_rough_surface_conserves_energy_both_polarisations(nk):
    """Rough surface, rms slope 0.3, 3 partitions of 60 lambda, 8 pts/lambda: reflected + absorbed within
    2 % of 1 for s and p (finite-sample tilt noise ~1 % at 40 deg); a metal absorbs a few percent."""
    ell = 3.0
    kw = {} if nk is None else {"n": nk[0], "k": nk[1]}
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", mom.MoMAccuracyWarning)  # short partitions (20 ell): not the point here
        res = mom.scatter(180.0, 3, 0.3 * ell / math.sqrt(2), ell, [0.0, 40.0], [0.0], pts_per_wl=8, seed=2,
                          executor=SERIAL, polarization=("s", "p"), **kw)
    np.testing.assert_allclose(res.energy_s, 1.0, atol=0.02)
    np.testing.assert_allclose(res.energy_p, 1.0, atol=0.02)
    if nk is not None:
        assert np.all((res.absorbed_s > 0.005) & (res.absorbed_s < 0.1))
        assert np.all((res.absorbed_p > 0.005) & (res.absorbed_p < 0.1))
    for key in ("M00", "M01", "M22", "M23"):
        assert res.mueller[key].shape == (2, 1) and np.all(np.isfinite(res.mueller_std_error[key]))


def test_model1d_mueller_reduces_to_fresnel():
    """The 1-D model's Mueller elements are the facet Fresnel terms at beta = (ti + tr)/2 times the
    specular term (diffuse off); a PEC gives M22 = -M00, M01 = M23 = 0."""
    from hyde_bsdf.model.fresnel import fresnel_mueller_terms
    from hyde_bsdf.model.index import Index

    ti = np.radians([[10.0], [50.0]])
    tr = np.radians([-20.0, 10.0, 45.0, 70.0])
    m = model1d.mueller_sigma(ti, tr, 0.44, *INFRAGOLD, diffuse=False)
    spec = model1d.sigma_equivalent(ti, tr, 0.44, diffuse=False)
    A, B, C, S = fresnel_mueller_terms(np.cos(0.5 * (ti + tr)), Index(*INFRAGOLD))
    np.testing.assert_allclose(m["M01"], spec * B, rtol=1e-12)
    np.testing.assert_allclose(m["M23"], spec * S, rtol=1e-12)
    pec = model1d.mueller_sigma(ti, tr, 0.44)
    np.testing.assert_allclose(pec["M22"] + model1d.sigma_equivalent(ti, tr, 0.44, diffuse=False), 0.0, atol=1e-12)
    np.testing.assert_allclose(pec["M00"], model1d.sigma_equivalent(ti, tr, 0.44), rtol=1e-12)


# --- issue 10: the MoM is never silently wrong ---

def test_steep_surface_is_refused_not_silently_wrong():
    """The issue's case (rms slope 8.5, steepest slope 24): 10 pts/lambda along x is 0.4 per wavelength
    of arc length; it used to return a power balance of 881.6 without a warning.  Resampling to 5 per
    wavelength of arc length needs 18,000 unknowns per partition: refused before any allocation."""
    for ppw in (10, 40):
        with pytest.raises(ValueError, match="arc length"):
            mom.scatter(300, 2, 30, 5.0, [30], np.arange(-89, 90.), pts_per_wl=ppw, seed=0, executor=SERIAL)


def test_moderately_steep_surface_is_resampled_along_arc_length():
    """rms slope 1.4: the steepest slope needs more than 6 pts/lambda along x; the surface is resampled
    (params says how finely).  The answer (converged in pts_per_wl: 1.269 at 14 and at 28 pts/lambda)
    is off 1 because one 40-lambda partition is far too short for this surface; the energy check says so."""
    ell = 2.0
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", mom.MoMAccuracyWarning)
        res = mom.scatter(40.0, 1, 1.4 * ell / math.sqrt(2), ell, [20.0], [0.0], pts_per_wl=6, seed=1,
                          executor=SERIAL)
    assert res.params["pts_per_wl"] > 6.0 * 1.5
    assert res.power_balance[0] == pytest.approx(1.269, abs=0.01)
    assert any("reflected + absorbed power is 1.269" in w for w in res.warnings)


def test_energy_failure_always_warns_with_its_value():
    """A windowed current with a taper too narrow for 80 deg: the power balance is off by > 5 %, and the warning
    says by how much."""
    with pytest.warns(mom.MoMAccuracyWarning, match=r"reflected \+ absorbed power is 0\.\d+ at 80 deg"):
        res = mom.scatter(40.0, 1, 0.0, 1.0, 80.0, 80.0, pts_per_wl=6, executor=SERIAL, incidence="window")
    assert abs(res.power_balance[0] - 1.0) > 0.05
    assert any("reflected + absorbed" in w for w in res.warnings)


@pytest.mark.parametrize("kwargs, name", [
    ({"seed": -1}, "seed"),
    ({"seed": 1.5}, "seed"),
    ({"taper_width_wl": 1e6}, "taper_width_wl"),
    ({"polarization": "x"}, "polarization"),
    ({"polarization": ("s", "s")}, "polarization"),
    ({"n": -1.0}, "n"),
    ({"k": 2.0}, "k"),
    ({"n": 1.0, "k": 1e5}, "k"),
    ({"n": 3.0, "pts_per_wl": 5.0}, "pts_per_wl"),
])
def test_bad_input_names_parameter(kwargs, name):
    args = {"length_wl": 20.0, "partitions": 1, "rms_height_wl": 0.0, "corr_length_wl": 1.0,
            "theta_i_deg": 0.0, "theta_r_deg": 0.0, "executor": SERIAL}
    args.update(kwargs)
    with pytest.raises(ValueError, match=name), warnings.catch_warnings():
        warnings.simplefilter("ignore", mom.MoMAccuracyWarning)
        mom.scatter(**args)


def test_coarse_interior_sampling_warns():
    """Glass n = 1.5 at 6 pts/lambda: 4 points per interior wavelength -- a warning naming it."""
    with pytest.warns(mom.MoMAccuracyWarning, match="interior wavelength"):
        mom.scatter(20.0, 1, 0.0, 1.0, 0.0, 0.0, pts_per_wl=6, executor=SERIAL, n=1.5, k=0.0)


def test_blas_thread_probe_leaves_no_file_open():
    """The OpenBLAS probe reads /proc/self/maps with a context manager: no ResourceWarning."""
    with warnings.catch_warnings():
        warnings.simplefilter("error", ResourceWarning)
        runtime.openblas_libs()
        gc.collect()


def test_dask_local_cluster_executor():
    """The partitions run on a dask.distributed LocalCluster (1 worker, 1 thread, in-process) and give the
    serial answer exactly (the `distributed` extra, installed by ./run.sh test)."""
    distributed = pytest.importorskip("distributed")
    args = (40.0, 2, 0.2, 1.5, [20.0], np.arange(-80, 81, 20.0))
    ref = mom.scatter(*args, pts_per_wl=6, seed=4, executor=SERIAL, polarization=("s", "p"))
    with distributed.LocalCluster(n_workers=1, threads_per_worker=1, processes=False, dashboard_address=None) \
            as cluster, distributed.Client(cluster) as client:
        res = mom.scatter(*args, pts_per_wl=6, seed=4, executor=client.get_executor(), polarization=("s", "p"))
    np.testing.assert_allclose(res.sigma_s, ref.sigma_s, rtol=1e-12)
    np.testing.assert_allclose(res.mueller["M22"], ref.mueller["M22"], rtol=1e-12, atol=1e-15)
