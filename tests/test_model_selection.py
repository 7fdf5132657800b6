"""Model adequacy (the verdict), model selection (``--model auto``) and robust standard errors.

Physics checked: a V-groove model cannot describe the lobe of a Smith-shadowed surface (and says
so, with the figure and the cause); the generating model fits its own table to float32 rounding
and 1 %-noisy copies within the noise; chi^2 of data with sigmas rejects a model without the
diffuse term's depolarization; selection recovers the generating shadowing x diffuse model; the
cluster-robust errors cover the truth where a smooth systematic misfit makes the classic ones 70x
too small, and have pulls of unit spread where the noise is heteroscedastic.
"""
import math
import warnings

import numpy as np
import pytest

from hyde_bsdf.fit import fit_mueller, synthetic_measurements
from hyde_bsdf.fit.adequacy import InadequateModelError, InadequateModelWarning, cluster_covariance, half_angles
from hyde_bsdf.fit.model_selection import select_model, select_model_pbsdf
from hyde_bsdf.fit.pbsdf_export import export_pbsdf
from hyde_bsdf.fit.pbsdf_samples import pbsdf_samples
from hyde_bsdf.fit.pbsdf_fit import fit_pbsdf

TRUTH = {"rms_slope": 0.2, "n": 1.5, "k": 3.0}
START = dict(TRUTH)


@pytest.fixture(scope="module")
def smith_table(tmp_path_factory):
    path = tmp_path_factory.mktemp("adequacy") / "smith.pbsdf"
    export_pbsdf(path, rms_slope=0.2, n=[1.5] * 5, k=[3.0] * 5, shadowing="smith", diffuse="none",
                 resolution=(9, 12, 12), error_samples=0, alpha_sample=0.3)
    return pbsdf_samples(path, max_points=200)


def _copy(data, F):
    return type(data)(**{**data.__dict__, "F": F})


def test_a_wrong_shadowing_is_flagged_with_its_figure_and_cause(smith_table):
    few = _copy(smith_table, smith_table.F)
    few.theta_i, few.theta_r, few.phi, few.F = (a[..., :80, :, :] if a.ndim > 1 else a[:80] for a in
                                                (smith_table.theta_i, smith_table.theta_r, smith_table.phi,
                                                 smith_table.F))
    with pytest.warns(InadequateModelWarning, match=r"M00 misfit .* %.*try `select_model`"):
        res = fit_pbsdf(few, fit=("k", "rms_slope"), n0=1.5, shadowing="vgroove", diffuse="paper", start=START,
                        progress=False)
    v = res.verdict
    assert not v.adequate and v.errors == "lower bounds"
    assert v.figures["M00_systematic"] > 0.5          # the lobe's shape: > 50 % rms, not float32 scatter
    text = res.summary()
    assert "optimizer converged: True" in text and "but the model does NOT describe the table" in text
    assert "LOWER BOUNDS" in text and "INADEQUATE" in text


def test_the_generating_model_is_adequate_noiseless_and_with_noise(smith_table):
    with warnings.catch_warnings():
        warnings.simplefilter("error", InadequateModelWarning)
        exact = fit_pbsdf(smith_table, shadowing="smith", diffuse="none", start=START, progress=False)
        rng = np.random.default_rng(7)
        F = smith_table.F * (1 + 0.01 * rng.standard_normal(smith_table.F.shape[:2]))[..., None, None]
        noisy = fit_pbsdf(_copy(smith_table, F), shadowing="smith", diffuse="none", start=START, progress=False)
    assert exact.verdict.adequate and exact.verdict.figures["M00_rms"] < 1e-5
    assert abs(exact.rms_slope / 0.2 - 1) < 1e-5
    # 1 % noise: all scatter, no trend; classic errors, and the truth within 4 of them
    assert noisy.verdict.adequate and noisy.verdict.errors == "classic"
    assert noisy.verdict.figures["M00_systematic"] < 0.3 * noisy.verdict.figures["M00_scatter"]
    assert abs(noisy.rms_slope - 0.2) < 4 * noisy.stderr["rms_slope"]


def test_robust_errors_cover_a_smooth_systematic_misfit(smith_table):
    th, _ = half_angles(smith_table.theta_i, smith_table.theta_r, smith_table.phi)
    F = smith_table.F * (1 + 0.003 * np.cos(3 * th))[None, :, None, None]     # 0.2 % rms, smooth in theta_h
    res = fit_pbsdf(_copy(smith_table, F), shadowing="smith", diffuse="none", start=START, progress=False)
    assert res.verdict.adequate and res.verdict.errors == "robust"   # within tolerance, but a trend
    classic = res.verdict.figures["stderr_classic"]["rms_slope"]
    assert abs(res.rms_slope - 0.2) / classic > 20                      # 71 measured
    assert abs(res.rms_slope - 0.2) / res.stderr["rms_slope"] < 2       # 1.07 measured


def test_cluster_jackknife_pulls_have_unit_spread_under_heteroscedastic_noise():
    rng = np.random.default_rng(3)
    x = np.linspace(0, 1, 200)
    J = np.stack([np.ones_like(x), x], 1)
    sd = 0.01 + 0.3 * x ** 4
    pulls, classic = [], []
    for _ in range(300):
        y = 1.0 + 2.0 * x + sd * rng.standard_normal(x.size)
        beta, *_ = np.linalg.lstsq(J, y, rcond=None)
        r = y - J @ beta
        cov = cluster_covariance(J, r, np.arange(x.size) // 5)      # 40 clusters of 5 neighbours
        pulls.append((beta[1] - 2.0) / math.sqrt(cov[1, 1]))
        classic.append((beta[1] - 2.0) / math.sqrt(np.linalg.inv(J.T @ J)[1, 1] * (r @ r) / (x.size - 2)))
    assert 0.85 < np.std(pulls) < 1.15
    assert np.std(classic) > 1.3       # the classic errors assume one noise level


def _csv(model, seed=1):
    th = np.radians([20.0, 45.0, 70.0])
    ti, tr, ph = (a.ravel() for a in np.meshgrid(th, np.radians(np.arange(10.0, 81.0, 10.0)),
                                                 np.radians([0.0, 90.0, 180.0]), indexing="ij"))
    return synthetic_measurements(ti, tr, ph, ("M01", "M10", "M11", "M22", "M23", "M33"), rms_slope=0.25,
                                  n=1.2, k=7.0, noise=0.03, n_samples=256, rng=seed,
                                  shadowing=model[0], diffuse=model[1])


def test_chi2_verdict_rejects_a_model_without_the_depolarization_and_strict_raises():
    m = _csv(("smith", "reciprocal"))
    args = (m.theta_i, m.theta_r, m.phi, m.values)
    with pytest.warns(InadequateModelWarning, match=r"reduced chi\^2 = .*p = "):
        bad = fit_mueller(*args, sigma=m.uncertainty(), fit=("n", "k"), rms_slope=0.25, shadowing="vgroove",
                          diffuse="none")
    assert not bad.verdict.adequate and bad.verdict.figures["p_value"] < 1e-3
    assert "optimizer converged: True" in bad.summary() and "does NOT describe the data" in bad.summary()
    with pytest.raises(InadequateModelError, match=r"reduced chi\^2"):
        fit_mueller(*args, sigma=m.uncertainty(), fit=("n", "k"), rms_slope=0.25, shadowing="vgroove",
                    diffuse="none", strict=True)
    with warnings.catch_warnings():
        warnings.simplefilter("error", InadequateModelWarning)
        good = fit_mueller(*args, sigma=m.uncertainty(), fit=("n", "k", "rms_slope"), rms_slope=0.25,
                           shadowing="smith", diffuse="reciprocal")
    assert good.verdict.adequate and good.verdict.figures["p_value"] > 1e-3 and good.verdict.errors == "classic"


@pytest.mark.parametrize("model", [("smith", "reciprocal"), ("none", "paper"), ("vgroove", "paper")])
def test_auto_picks_the_generating_model_from_csv_data(model):
    m = _csv(model)
    sel = select_model(m.theta_i, m.theta_r, m.phi, m.values, sigma=m.uncertainty(), fit=("n", "k", "rms_slope"))
    assert (sel.choice.shadowing, sel.choice.diffuse) == model and sel.result.verdict.adequate
    assert abs(sel.result.params["k"] / 7.0 - 1) < 0.01 and "BIC" in sel.summary()


def test_auto_picks_smith_without_diffuse_from_its_table(smith_table):
    sel = select_model_pbsdf(smith_table, progress=False)
    assert sel.choice.label == "smith/none" and sel.result.verdict.adequate
    assert abs(sel.result.rms_slope / 0.2 - 1) < 1e-4 and np.allclose(sel.result.k, 3.0, rtol=1e-4)
    text = sel.summary()
    assert "none/reciprocal" in text and "undefined" in text and "<- chosen" in text
    rejected = [r for r in sel.rows if r.stage != "undefined" and not r.adequate]
    assert {r.label for r in rejected} >= {"vgroove/paper", "smith/paper"}


def test_cli_strict_exits_1_on_an_inadequate_fit_after_printing_the_verdict(smith_table, tmp_path, capsys):
    from hyde_bsdf.app.cli import main

    path = smith_table.source
    code = main(["fit", str(path), "--max-points", "60", "--shadowing", "vgroove", "--strict", "-q"])
    out, err = capsys.readouterr()
    assert code == 1
    assert "INADEQUATE" in out and "but the model does NOT describe the table" in out
    assert "--strict: M00 misfit" in err and "try --model auto" in err
    # the same fit without --strict still says so, but exits 0
    assert main(["fit", str(path), "--max-points", "60", "--shadowing", "vgroove", "-q"]) == 0
    assert "WARNING: M00 misfit" in capsys.readouterr().out


def test_cli_chooses_the_model_unless_one_is_named(smith_table, tmp_path, capsys):
    from hyde_bsdf.app.cli import main

    code = main(["fit", str(smith_table.source), "--max-points", "200", "-q", "-o", str(tmp_path / "fit.png")])
    out = capsys.readouterr().out
    assert code == 0 and "model selection" in out and "chosen: smith/none" in out
    assert (tmp_path / "fit.png").is_file() and (tmp_path / "fit_models.png").is_file()
    assert main(["fit", str(smith_table.source), "--model", "auto", "--diffuse", "none"]) == 2
    assert "--model auto chooses" in capsys.readouterr().err


def test_cli_refuses_a_fifo_at_the_models_plot_before_fitting(smith_table, tmp_path, capsys):
    """--model auto writes NAME_models.EXT beside -o NAME.EXT: that file passes the output gate too
    (a FIFO there is refused with one line, exit 2, before any fit, and is left as it was)."""
    import os
    import stat

    from hyde_bsdf.app.cli import main

    fifo = tmp_path / "plot_models.png"
    os.mkfifo(fifo)
    code = main(["fit", str(smith_table.source), "--max-points", "60", "-o", str(tmp_path / "plot.png"), "-q"])
    out, err = capsys.readouterr()
    assert code == 2 and err.count("\n") == 1 and "plot_models.png" in err and "FIFO" in err, err
    assert stat.S_ISFIFO(os.lstat(fifo).st_mode) and not (tmp_path / "plot.png").exists()
    assert "rms_slope" not in out                     # refused before the fit
