"""Polarimetric material capture: per-texel index (eta; n and k of a metal), roughness and scale maps
from designed Stokes observations, with standard-error maps -- and what the S0 (intensity) loss
cannot do.

Two synthetic samples (2 x 2 planes carrying ``hyde`` with nearest-neighbour texture maps, rows
along v), each seen in the designed acquisition of :func:`hyde_bsdf.inverse.design_acquisition`
(distant Stokes cameras, directional lights, 5 mirror pairs at facet angles 10-70 deg + 2
off-specular pairs; ``llvm_ad_mono_polarized``):

* ``dielectric``: an eta map (a gradient 1.3 -> 2.2 along u plus a sharp-edged patch at 2.0),
  k = 0, an alpha map (gradient 0.15 -> 0.4 plus a sharp patch at 0.5); unpolarized light;
* ``metal``: n from gold-like 0.45 to aluminium-like 1.2 along u, k from 2.4 to 6.7 along v, a
  sharp patch (n 0.7, k 4.0), an alpha map; the mirror pairs behind a linear polarizer at 45 deg
  (Mitsuba's ``polarizer`` sheet, ``stokes`` + ``volpath``), so the retardance elements M22, M32
  enter, plus circular light (polarizer 0 deg + ``retarder`` quarter-wave at 45 deg: M23, M33) at
  beta = 50 and 65 deg -- 9 pictures, the ``"metal"`` preset, designed with
  :func:`hyde_bsdf.inverse.predicted_stderr` for n, the weakly determined parameter.

References: rendered from the truth at ``spp_ref`` samples plus Gaussian camera noise (1 % of the
median lit S0, on each Stokes component).  Each case is fitted four times from constant start maps
(alpha 0.3, eta 1.6 / n 0.8, k 4, scale 1) with :func:`hyde_bsdf.inverse.invert_maps` (Adam in log
values, 4 spp, 60 iterations, then 3 Gauss-Newton steps weighted by the noise and the standard
errors from forward-mode AD at 8 spp):

* ``stokes``: the Stokes loss, scale known (``specular_reflectance`` = 1);
* ``s0``: the S0-only loss, scale known;
* ``stokes+scale``: the truth has a per-texel scale map (0.6-1.4: an unknown albedo or an
  uncalibrated light) fitted jointly with the index and alpha, from a *fixed rig*
  (:func:`hyde_bsdf.inverse.fixed_rig_acquisition`: camera and light 2 beta apart, beta = 50 deg
  dielectric / 60 deg metal, the sample tilted by -16..16 deg; every picture at one facet angle) --
  the Stokes images still determine the index, because the scale cancels in the ratios B/A, C/A, S/A;
* ``s0+scale``: the same with the S0 loss, where the index is *not* determined (the scale absorbs
  the Fresnel factor F(beta; index), the same in every picture): ``invert_maps`` warns, naming the
  parameter and the fraction of texels (an :class:`~hyde_bsdf.inverse.UnidentifiedParameterWarning`);
  the check is that it does.  (With the full design's facet angles 10-70 deg, S0 alone does
  determine the index even with an unknown scale -- the shape of F against beta carries it:
  measured in tests/test_inverse_capture.py's tiny case, relative standard error 0.2-3 %.)

Errors are per texel over the texels the pictures see (every texel here); the pull
(fit - truth) / standard error over those texels has a standard deviation near 1 when the standard
errors are right (checked 0.8-1.25 in the full run, with the accuracy targets).  The quick run (the
report's quick mode, ~15 s: the dielectric's two unknown-scale runs only, 4 x 4 texels of 4 x 4 px,
a fixed rig of 2 pictures at tilts 0 and 12 deg, 10 unfrozen iterations + 2 Gauss-Newton steps)
checks the identifiability statements: S0 flags eta, the Stokes images determine it (relative
standard error <= 10 % and 10x smaller).  The metal's quick form is in tests/test_inverse_capture.py
(its volpath pictures cost more than the quick report may spend).

Writes ``svbrdf_index.png`` (per case and map: truth, recovered, error and standard error for the
Stokes loss; recovered and error for the S0 loss; the index error and standard error of the two
unknown-scale runs) and ``svbrdf_index.csv`` (one row per case, loss and parameter:
``case, loss, parameter, median_rel_err, p90_rel_err, pull_std``, plus the median relative standard
error, the fraction of texels flagged, seconds).

    python validation/svbrdf_index.py [-o OUTDIR] [--quick]

The full run writes the CSV and the picture after each of its 8 fits (the metal's and the
dielectric's Stokes fits first), so a run stopped early leaves what it finished.
"""
from __future__ import annotations

import sys
import time
import warnings
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import cli, save_figure, write_csv  # noqa: E402

from hyde_bsdf import inverse as inv  # noqa: E402
from hyde_bsdf.inverse.uncertainty import STDERR_THRESHOLD  # noqa: E402
from hyde_bsdf.inverse.acquisition import (design_acquisition, example_material,  # noqa: E402
                                           fixed_rig_acquisition, synthetic_observations)
from hyde_bsdf.progress import stderr_lines  # noqa: E402

_log = stderr_lines("[invert]")

#: targets of the full run (issue 16): (median, 90th percentile) of |fit / truth - 1|
TARGETS = {"eta": (0.01, 0.03), "alpha": (0.03, 0.08), "n": (0.03, 0.10), "k": (0.03, 0.10)}
PULL_BAND = (0.8, 1.25)
NOISE = 0.01
CASES = ("metal", "dielectric")
QUICK_ITERATIONS = 10
#: the quick rig's two tilts (deg): unequal half-vector tilts, so that the lobe's width and the scale
#: are told apart (two symmetric tilts see one lobe value: alpha and the scale then trade off)
QUICK_TILTS = (0.0, 12.0)
#: the full run's fits (case, loss, unknown scale) in the order they run: the targets' Stokes fits
#: first, then the unknown-scale pairs, then the S0 fits with the scale known
RUNS = tuple((c, "stokes", False) for c in CASES) + tuple((c, l, True) for c in CASES for l in ("stokes", "s0")) \
    + tuple((c, "s0", False) for c in CASES)
#: the unknown-scale runs' fixed rig: one facet angle (deg) for every picture
RIG_FACET_ANGLE = {"dielectric": 50.0, "metal": 60.0}


def truth_maps(case: str, n: int) -> dict:
    """The truth of a case on an n x n map (:func:`hyde_bsdf.inverse.example_material`)."""
    return example_material(case, n)


def start_values(case: str) -> dict:
    return {"alpha": 0.3, "eta": 1.6} if case == "dielectric" else {"alpha": 0.3, "eta": 0.8, "k": 4.0}


def observations(case: str, scale: bool, *, n: int, res: int, spp_ref: int, facet_angles=None, seed: int = 0):
    """The truth maps, start values, fitted names and observations of one case (shared by its two losses:
    each fit starts by writing the start maps into the scenes)."""
    truth = truth_maps(case, n)
    if not scale:
        truth["specular_reflectance"] = 1.0
    start = start_values(case)
    if scale:
        start["specular_reflectance"] = 1.0
    if scale:        # one facet angle for every picture: the scale absorbs F(beta; index) in S0
        acq = fixed_rig_acquisition(case, facet_angle=RIG_FACET_ANGLE[case],
                                    tilts=(-16.0, -8.0, 0.0, 8.0, 16.0) if facet_angles is None else QUICK_TILTS)
    else:
        acq = design_acquisition(case, **({} if facet_angles is None else {"facet_angles": facet_angles}))
    obs = synthetic_observations(acq, truth, start, res=res, spp=4, spp_ref=spp_ref, noise=NOISE, seed=seed)
    return truth, start, tuple(start), obs


def run_case(case: str, loss: str, prepared, *, iterations: int, uncertainty_spp: int, polish: int = 2,
             seed: int = 0, freeze: bool = True):
    """One fit of ``prepared`` (:func:`observations`); returns (result, truth of the fitted maps, caught
    warning messages, seconds)."""
    truth, start, fit, obs = prepared
    t0 = time.perf_counter()
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", inv.UnidentifiedParameterWarning)
        res_ = inv.invert_maps(obs, start, fit=fit, iterations=iterations, spp=4, seed=seed + 7, components=loss,
                               truth={k: np.asarray(truth[k], float) for k in fit}, progress=False,
                               uncertainty_spp=uncertainty_spp, polish=polish, freeze=freeze)
    msgs = [str(w.message) for w in caught if issubclass(w.category, inv.UnidentifiedParameterWarning)]
    return res_, {k: truth[k] for k in fit}, msgs, time.perf_counter() - t0


CSV_HEADER = ["case", "loss", "parameter", "median_rel_err", "p90_rel_err", "pull_std", "median_rel_stderr",
              "fraction_flagged", "seconds"]


def _stats(key, result, stats) -> list:
    """The CSV rows of one run ``key`` = (case, loss); fills ``stats[(case, loss, name)]``."""
    (case, loss), (r, truth, msgs, secs) = key, result
    rows = []
    for name in truth:
        e = r.texel_errors(name)
        z = r.pulls(name)
        z = z[np.isfinite(z)]
        rel = r.rel_stderr[name][r.seen]
        flagged = float(np.mean(~(rel <= r.uncertainty.threshold)))
        st = dict(median=float(np.median(e)), p90=float(np.percentile(e, 90)),
                  pull_std=float(np.std(z)) if z.size > 2 else float("nan"),
                  rel_se=float(np.nanmedian(rel)) if (~np.isnan(rel)).any() else float("nan"), flagged=flagged, warned=any(m.startswith(name + " ") for m in msgs))
        stats[(case, loss, name)] = st
        rows.append([case, loss, _label(case, name), f"{st['median']:.5f}", f"{st['p90']:.5f}",
                     f"{st['pull_std']:.3f}", f"{st['rel_se']:.5f}", f"{flagged:.3f}", f"{secs:.1f}"])
    return rows


def _label(case, name):
    return {"eta": "n" if case == "metal" else "eta"}.get(name, name)


def validate(outdir="out/validation", quick=False):
    import mitsuba as mi

    out = Path(outdir)
    out.mkdir(parents=True, exist_ok=True)
    previous = mi.variant()
    inv.prepare(inv.MAP_VARIANT)
    if quick:      # the dielectric's unknown-scale runs: 4 x 4 texels of 4 x 4 px, the fixed rig's 2 pictures
        cfg = dict(n=4, res=16, iterations=QUICK_ITERATIONS, spp_ref=32, uncertainty_spp=4,
                   facet_angles=(10.0, 40.0, 70.0), polish=2, freeze=False)
        runs = tuple(("dielectric", loss, True) for loss in ("stokes", "s0"))
    else:
        cfg = dict(n=32, res=128, iterations=60, spp_ref=256, uncertainty_spp=8, polish=3)
        runs = RUNS
    results = {}
    fitcfg = {k: cfg[k] for k in ("iterations", "uncertainty_spp", "polish", "freeze") if k in cfg}
    obscfg = {k: cfg[k] for k in ("n", "res", "spp_ref") if k in cfg}
    obscfg["facet_angles"] = cfg.get("facet_angles")
    rows, stats = [], {}
    try:
        prepared = {}
        for case, loss, scale in runs:
            if True:
                key = (case, loss + ("+scale" if scale else ""))
                _log(f"[svbrdf_index] {key[0]}, {key[1]} loss ({cfg['n']}x{cfg['n']} maps, "
                         f"{cfg['res']} px per view, {cfg['iterations']} iterations)")
                if (case, scale) not in prepared:
                    prepared = {(case, scale): observations(case, scale, **obscfg)}     # one case's pictures at a time
                results[key] = run_case(case, loss, prepared[(case, scale)], **fitcfg)
                rows += _stats(key, results[key], stats)
                # the table so far (a long full run leaves its finished rows behind if stopped)
                write_csv(out / "svbrdf_index.csv", CSV_HEADER, rows)
                _log(f"[svbrdf_index] {key[0]}, {key[1]}: {results[key][3]:.0f} s; " + "; ".join(
                    f"{r[2]} {100 * float(r[3]):.2f} % / {100 * float(r[4]):.2f} %, pulls {r[5]}"
                    for r in rows if (r[0], r[1]) == key))
                _plot(out / "svbrdf_index.png", results, cfg)
    finally:
        if previous is not None and previous != mi.variant():
            mi.set_variant(previous)

    checks = []
    for case in [c for c in CASES if (c, "s0+scale", "eta") in stats or not quick]:
        if not quick:          # the targets of the issue, on 32 x 32 maps
            for name in ("alpha", "eta") + (("k",) if case == "metal" else ()):
                lab = _label(case, name)
                tmed, tp90 = TARGETS[lab]
                for loss in [x for x in ("stokes", "stokes+scale") if (case, x, name) in stats]:
                    st = stats[(case, loss, name)]
                    checks.append(dict(name=f"{case}, {loss} loss: {lab} map, median | p90 per-texel |fit/truth - 1|",
                                       value=f"{100 * st['median']:.2f} % | {100 * st['p90']:.2f} %",
                                       tolerance=f"<= {100 * tmed:g} % | <= {100 * tp90:g} %",
                                       passed=st["median"] <= tmed and st["p90"] <= tp90))
                    checks.append(dict(name=f"{case}, {loss} loss: {lab} pulls (fit - truth) / standard error, std",
                                       value=f"{st['pull_std']:.2f}", tolerance=f"{PULL_BAND[0]:g}-{PULL_BAND[1]:g}",
                                       passed=PULL_BAND[0] <= st["pull_std"] <= PULL_BAND[1]))
        idx = ("eta",) if case == "dielectric" else ("eta", "k")
        for name in idx:
            lab = _label(case, name)
            s0 = stats[(case, "s0+scale", name)]
            st = stats[(case, "stokes+scale", name)]
            checks.append(dict(
                name=f"{case}, unknown per-texel scale, fixed rig: {lab} from S0 alone is flagged as not determined "
                     f"(UnidentifiedParameterWarning; % of texels, median relative standard error)",
                value=f"warned: {s0['warned']}, {100 * s0['flagged']:.0f} % of texels, rel. SE {100 * s0['rel_se']:.3g} %",
                tolerance="warned, > 50 % of texels", passed=s0["warned"] and s0["flagged"] > 0.5))
            checks.append(dict(
                name=f"{case}, unknown per-texel scale, fixed rig: the Stokes images determine {lab} "
                     f"(median relative standard error, Stokes / S0)",
                value=f"{100 * st['rel_se']:.3g} % / {100 * s0['rel_se']:.3g} %",
                tolerance=f"Stokes <= {100 * STDERR_THRESHOLD:g} % and < S0 / 10",
                passed=st["rel_se"] <= STDERR_THRESHOLD and st["rel_se"] < s0["rel_se"] / 10))
    print(f"{'case':11s} {'loss':13s} {'param':6s} {'median':>8s} {'p90':>8s} {'pull sd':>8s} {'rel SE':>8s} "
          f"{'flagged':>8s}")
    for (case, loss, name), st in stats.items():
        print(f"{case:11s} {loss:13s} {_label(case, name):6s} {100 * st['median']:7.2f}% {100 * st['p90']:7.2f}% "
              f"{st['pull_std']:8.2f} {100 * st['rel_se']:7.2f}% {100 * st['flagged']:7.0f}%")
    return checks


def _plot(path, results, cfg):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    # every run present so far (a full run draws its picture after each run)
    panels = []
    for case in CASES:
        full = (case, "stokes") in results
        if (case, "stokes" if full else "stokes+scale") not in results:
            continue
        r, truth, _, _ = results[(case, "stokes" if full else "stokes+scale")]
        r0 = results.get((case, "s0" if full else "s0+scale"), (None,))[0]
        for name in truth:
            panels.append((case, name, r, r0, truth[name]))
    scale_cases = [c for c in CASES if (c, "stokes+scale") in results and (c, "s0+scale") in results]
    ncol = 6
    nrow = max(1, len(panels) + len(scale_cases))
    fig, axes = plt.subplots(nrow, ncol, figsize=(3.0 * ncol, 2.7 * nrow), layout="constrained", squeeze=False)
    kw = dict(origin="lower", extent=(0, 1, 0, 1))
    for row, (case, name, r, r0, t) in enumerate(panels):
        lab = _label(case, name)
        vmin, vmax = float(np.min(t)), float(np.max(t))
        ax = axes[row]
        ax[0].imshow(t, vmin=vmin, vmax=vmax, **kw)
        ax[0].set_title(f"{case}: truth {lab}", fontsize=8)
        im = ax[1].imshow(r.final[name], vmin=vmin, vmax=vmax, **kw)
        ax[1].set_title("recovered, Stokes loss", fontsize=8)
        fig.colorbar(im, ax=ax[1], shrink=0.7)
        e = 100 * (r.final[name] / t - 1)
        lim = max(1.0, float(np.percentile(np.abs(e), 95)))
        im = ax[2].imshow(e, cmap="RdBu_r", vmin=-lim, vmax=lim, **kw)
        ax[2].set_title("error %, Stokes", fontsize=8)
        fig.colorbar(im, ax=ax[2], shrink=0.7)
        im = ax[3].imshow(100 * r.rel_stderr[name], cmap="magma", **kw)
        ax[3].set_title("standard error %, Stokes", fontsize=8)
        fig.colorbar(im, ax=ax[3], shrink=0.7)
        if r0 is None:
            continue
        ax[4].imshow(r0.final[name], vmin=vmin, vmax=vmax, **kw)
        ax[4].set_title("recovered, S0 loss", fontsize=8)
        e0 = 100 * (r0.final[name] / t - 1)
        im = ax[5].imshow(e0, cmap="RdBu_r", vmin=-lim, vmax=lim, **kw)
        ax[5].set_title("error %, S0 loss", fontsize=8)
        fig.colorbar(im, ax=ax[5], shrink=0.7)
    for k, case in enumerate(scale_cases):
        ax = axes[len(panels) + k]
        rs, truth, _, _ = results[(case, "stokes+scale")]
        r0 = results[(case, "s0+scale")][0]
        c = 0
        for name in [n for n in ("eta", "k") if n in truth]:
            lab = _label(case, name)
            for rr, tag in ((rs, "Stokes"), (r0, "S0")):
                e = 100 * (rr.final[name] / truth[name] - 1)
                im = ax[c].imshow(e, cmap="RdBu_r", vmin=-20, vmax=20, **kw)
                ax[c].set_title(f"{case}, unknown scale: {lab} error %, {tag}", fontsize=7)
                fig.colorbar(im, ax=ax[c], shrink=0.7)
                c += 1
        for name, rr, tag in (("eta", rs, "Stokes"), ("eta", r0, "S0")):
            if c < ncol:
                im = ax[c].imshow(np.minimum(100 * rr.rel_stderr[name], 100), cmap="magma", **kw)
                ax[c].set_title(f"{_label(case, name)} standard error %, {tag}", fontsize=7)
                fig.colorbar(im, ax=ax[c], shrink=0.7)
                c += 1
        for a in ax[c:]:
            a.axis("off")
    for a in axes.ravel():
        if not a.images:
            a.axis("off")
        a.set_xticks([])
        a.set_yticks([])
    fig.suptitle(f"Per-texel index, roughness and scale from designed Stokes observations "
                 f"({cfg['n']}x{cfg['n']} maps, {cfg['res']} px per picture, {cfg['iterations']} iterations + "
                 f"{cfg['polish']} Gauss-Newton steps; noise {100 * NOISE:g} % of S0)", fontsize=10)
    save_figure(fig, path, dpi=80)


if __name__ == "__main__":
    cli(validate, __doc__)
