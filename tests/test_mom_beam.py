"""Tests of the MoM's incidence near grazing (hyde_bsdf.mom.beam, issue 25).

Physics checked: the windowed current of Eq. 22 reflects, off a flat PEC plate, the power that the exact
integral beam.window_bias predicts (s above 1, p below, ~0.82 tau and -0.26 tau); a Gaussian beam (an exact
Helmholtz solution, its power from its spectrum) is reflected with power 1 in both polarisations; no run of a
grid of flat and rough PEC surfaces at 80/85/88 deg is off in energy by more than the stated tolerance without a
warning; and the beam's far field at forward grazing follows the analytic reflected beam where the windowed
current shows its artificial s floor.
"""
from __future__ import annotations

import math
import warnings

import numpy as np
import pytest

from hyde_bsdf import mom
from hyde_bsdf.mom import beam

SERIAL = mom.SerialExecutor()
K0 = 2.0 * math.pi
ELL = 5.0
SIGMA_H = 0.3 * ELL / math.sqrt(2.0)


def _flat(theta_i, w, incidence, factor=4.0, theta_r=None):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", mom.MoMAccuracyWarning)
        return mom.scatter(factor * w, 1, 0.0, 1.0, [theta_i], [theta_i] if theta_r is None else theta_r,
                           executor=SERIAL, taper_width_wl=w, polarization=("s", "p"), solver="fast",
                           incidence=incidence)


def test_window_bias_law():
    """Exact integral against its first-order form 1 + (1 + 3 tan^2)/(2 (k w cos)^2) (s), 1 - 1/(2 (k w cos^2)^2) (p),
    within 3 % of the deviation at tau = 0.005; at tau = 0.0195 (80 deg): s 1 + 0.82 tau, p 1 - 0.26 tau."""
    t = math.radians(80.0)
    for tau in (0.005, 0.0195):
        w = math.sqrt((1 + 2 * math.tan(t) ** 2) / tau) / (K0 * math.cos(t))
        s, p = beam.window_bias(t, w, "s")[0] - 1, beam.window_bias(t, w, "p")[0] - 1
        kwc = K0 * w * math.cos(t)
        if tau == 0.005:
            assert s == pytest.approx((1 + 3 * math.tan(t) ** 2) / (2 * kwc ** 2), rel=0.03)
            assert p == pytest.approx(-1 / (2 * kwc ** 2 * math.cos(t) ** 2), rel=0.03)
        else:
            assert s / tau == pytest.approx(0.82, abs=0.01) and p / tau == pytest.approx(-0.26, abs=0.01)


@pytest.mark.parametrize("theta_i", [80.0, 85.0])
def test_flat_plate_power_window_against_beam(theta_i):
    """Flat PEC, Thorsos' tau = 0.05, 10 pts/lambda: the windowed current's power is window_bias within 0.004 in s
    (measured +0.2-0.3 %: sampling) and 0.001 in p (measured 1.054 / 0.986); the beam's is 1 within 0.004 (s) and
    0.0005 (p) (measured 1.0026 / 1.0000)."""
    t = math.radians(theta_i)
    w = math.sqrt((1 + 2 * math.tan(t) ** 2) / 0.05) / (K0 * math.cos(t))
    win = _flat(theta_i, w, "window")
    assert abs(win.energy_s[0] - beam.window_bias(t, w, "s")[0]) < 0.004
    assert abs(win.energy_p[0] - beam.window_bias(t, w, "p")[0]) < 0.001
    lit = _flat(theta_i, w, "beam")
    assert abs(lit.energy_s[0] - 1) < 0.004 and abs(lit.energy_p[0] - 1) < 0.0005
    assert lit.params["incidence"] == ["beam"]


def test_no_silent_energy_error_on_the_grazing_grid():
    """Flat and rough PEC (Fig. 6 statistics), 80/85/88 deg, windowed current and beam, the package's defaults
    (w = L_p / 4, 10 pts/lambda, partitions of 200 lambda): every run whose reflected power is off 1 by more than
    ENERGY_TOLERANCE in either polarisation carries a warning (12 runs; the windowed ones all warn beforehand, the
    beam's are within 1 % but rough at 88 deg, 1.02 / 1.03, which warns after the solve)."""
    silent_off = []
    for sigma_h, m in ((0.0, 1), (SIGMA_H, 2)):
        for theta_i in (80.0, 85.0, 88.0):
            for incidence in ("window", "beam"):
                with warnings.catch_warnings(record=True) as caught:
                    warnings.simplefilter("always", mom.MoMAccuracyWarning)
                    r = mom.scatter(200.0 * m, m, sigma_h, ELL, [theta_i], [theta_i], seed=1, executor=SERIAL,
                                    polarization=("s", "p"), incidence=incidence, progress=False)
                err = max(abs(r.energy_s[0] - 1), abs(r.energy_p[0] - 1))
                if err > mom.solver.ENERGY_TOLERANCE and not caught:
                    silent_off.append((sigma_h, theta_i, incidence, err))
                if incidence == "window":
                    assert any("taper too narrow" in str(w.message) for w in caught)
    assert silent_off == []


def test_forward_grazing_floor_of_the_windowed_current():
    """Flat PEC, 80 deg, w = 75 lambda, partition 6 w: at theta_r = 86 deg the analytic reflected beam is -82 dB below
    the specular peak; the beam's MoM p follows it within 3 dB at 86-87 deg and stays below -95 dB at 88-89 (s too,
    its numerical floor), where the windowed current's s sits at about -50 dB: the surface waves its plane-wave-lit
    partition ends launch (they decay only as x^-3/2 in s; -44.5 dB at 4 w)."""
    from hyde_bsdf.validation import mom_forward_grazing as fg

    tr = np.array([86.0, 87.0, 88.0, 89.0])
    ref = fg.beam_reference(80.0, 75.0, tr)
    peak = float(fg.beam_reference(80.0, 75.0, np.array([80.0]))[0])
    lit = _flat(80.0, 75.0, "beam", 6.0, tr)
    win = _flat(80.0, 75.0, "window", 6.0, tr)
    db = lambda v: 10 * np.log10(v / peak)  # noqa: E731
    assert np.all(np.abs(db(lit.sigma_p[0, :2]) - db(ref[:2])) < 3.0)
    assert np.all(db(lit.sigma_p[0, 2:]) < -95.0) and np.all(db(lit.sigma_s[0, 1:]) < -95.0)
    assert np.all(db(win.sigma_s[0]) > -56.0)


@pytest.mark.parametrize("n, k, factor", [(1.5, 0.0, 4.0), (0.285, 7.3523, 6.0)])
def test_glass_and_infragold_plates_window_against_beam(n, k, factor):
    """Flat glass and Infragold at 80 deg, tau = 0.0195 (w = 53 lambda): the windowed current's reflected + absorbed
    power is off by 1.1-2.2 % in both polarisations (measured glass 1.015 / 1.011, Infragold 1.019 / 1.022) and
    the set-up warning gives the estimate (the s law, +1.6 %, for p too); the beam's is 1 within 0.4 %
    (measured 1.0023 / 1.0020 and 1.0026 / 1.0010)."""
    t = math.radians(80.0)
    w = math.sqrt((1 + 2 * math.tan(t) ** 2) / 0.0195) / (K0 * math.cos(t))
    kw = dict(executor=SERIAL, taper_width_wl=w, polarization=("s", "p"), n=n, k=k, solver="fast")
    with pytest.warns(mom.MoMAccuracyWarning, match=r"estimated power error of s \+1\.6 %, p \+1\.6 % \(flat-plate s"):
        win = mom.scatter(factor * w, 1, 0.0, 1.0, [80.0], [80.0], incidence="window", **kw)
    assert win.energy_s[0] > 1.01 and win.energy_p[0] > 1.01
    with warnings.catch_warnings():
        warnings.simplefilter("error", mom.MoMAccuracyWarning)
        lit = mom.scatter(factor * w, 1, 0.0, 1.0, [80.0], [80.0], **kw)
    assert lit.params["incidence"] == ["beam"]
    assert abs(lit.energy_s[0] - 1) < 0.004 and abs(lit.energy_p[0] - 1) < 0.004


def test_partition_floor_flags_forward_grazing_of_the_truncated_partition():
    """Flat PEC plate, beam (issue 25, item 2): every sigma reported valid (sigma >= FLOOR_MARGIN x the estimated
    floor of the truncated partition) is within 3 dB of the analytic reflected beam -- w = 75 lambda at 80 deg on
    partitions of 4 w and 6 w (the truncation floor at 86-89 deg, -54 to -59 dB below the peak at 4 w where the
    analytic result is -82 to -126 dB, flagged), w = 37.5 at 83 deg on 6 w (86-89 deg valid: measured within
    1.5 dB), w = 20 at 85 deg on 4 w (a spectrum clipped at grazing: its backward-side floor, 25 dB below the peak,
    flagged) -- with a reason naming the partition."""
    from hyde_bsdf.validation.mom_forward_grazing import beam_reference

    theta_r = np.arange(20.0, 89.76, 0.25)
    for f, w, ti, at_grazing in ((4, 75.0, 80.0, 0), (6, 75.0, 80.0, 0), (6, 37.5, 83.0, 4), (4, 20.0, 85.0, 0)):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", mom.MoMAccuracyWarning)
            res = mom.scatter(f * w, 1, 0.0, 5.0, [ti], theta_r, pts_per_wl=10, executor=mom.SerialExecutor(),
                              taper_width_wl=w, polarization=("s", "p"), solver="fast", incidence="beam",
                              progress=False)
        ref = beam_reference(ti, w, theta_r)
        for pol in ("s", "p"):
            valid = getattr(res, "valid_" + pol)[0]
            sigma = getattr(res, "sigma_" + pol)[0]
            assert valid.sum() >= 15  # the lobe
            err = np.abs(10.0 * np.log10(sigma[valid] / ref[valid]))
            assert err.max() <= 3.0, (f, w, ti, pol, err.max())
            assert valid[theta_r >= 86.0].sum() >= at_grazing, (f, w, ti, pol)
            if at_grazing == 0:
                assert not valid[theta_r >= 86.0].any()
        assert np.array_equal(res.valid, res.valid_s)
        assert "truncated partition" in res.floor_reason and f"L = {f:g} w" in res.floor_reason
