"""Material capture with real polarization cameras: raw analyzer frames with a stated camera noise
model -> the least-squares Stokes step -> per-texel maps with standard errors, for a linear-only
(division-of-focal-plane) camera side by side with a full-Stokes camera.

The camera (:data:`NOISE`): EMVA 1288 linear model, gain 1 DN per electron, read noise 3 e-, full well
30 000 e-, black level 64 DN; the exposure puts the median lit S0 at :data:`SIGNAL` = 5000 DN
(saturated pixels are masked out).  ``linear``: a DoFP mosaic (Sony layout 90/45/135/0, each Stokes
pixel one super-pixel), demosaicked by super-pixel -- S0, S1, S2 with their propagated sigma;
``stokes``: six frames (analyzers 0/45/90/135 deg, then 45 and 135 deg behind a quarter-wave
retarder) -- S0..S3.  The sigma maps are the loss's weights and the standard errors' noise
(:mod:`hyde_bsdf.inverse.camera_data`, :mod:`hyde_bsdf.model.polarimetry`).

Cases (``hyde`` on a 2 x 2 plane, :func:`hyde_bsdf.inverse.acquisition.example_material`, scale known):

* ``dielectric``: the dielectric preset (5 unpolarized mirror pairs + 2 off-specular pairs);
* ``metal``: with the linear camera the linear metal preset -- a 45 deg polarizer and circular light
  (polarizer + quarter-wave retarder) on every mirror pair (12 pictures); with the full-Stokes
  camera the metal preset (9 pictures);
* ``metal_unpolarized``: the metal under unpolarized light only (7 pictures): n and k are not
  determined with either camera -- the check is that both are *warned*, never reported silently.

Targets (issue 23, full run, 32 x 32 texels; median / 90th percentile of |fit / truth - 1|): dielectric
linear eta <= 1 / 3 %, alpha <= 3 / 8 %; metal linear n, k <= 3 / 10 %, alpha <= 3 / 8 %; pull std in
0.8-1.25 wherever a standard error is reported (the determined cases); the Stokes step's sigma
against the scatter of 100 repeated captures of one rendered picture, ratio within 10 %; time per
iteration and picture of the linear-only fit against the full-Stokes fit (same run), <= 1.1.

Writes ``capture_camera.png`` (median and 90th-percentile errors per case, parameter and camera, the
pull std, the sigma check) and ``capture_camera.csv``.

    python hyde_bsdf/validation/capture_camera.py [-o OUTDIR] [--quick]

The quick mode (the report's and the tests'): the dielectric on 4 x 4 texels of 4 x 4 px, 3 pictures,
10 unfrozen iterations, both cameras, plus the sigma check.
"""
from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from hyde_bsdf.validation._common import cli, save_figure, write_csv  # noqa: E402
from hyde_bsdf.validation.svbrdf_index import CSV_HEADER, _stats, run_case, start_values  # noqa: E402

from hyde_bsdf import inverse as inv  # noqa: E402
from hyde_bsdf.inverse.acquisition import design_acquisition, example_material, synthetic_observations  # noqa: E402
from hyde_bsdf.model.polarimetry import CameraNoise, simulate_capture  # noqa: E402
from hyde_bsdf.progress import stderr_lines  # noqa: E402

_log = stderr_lines("[capture_camera]")

NOISE = CameraNoise(gain=1.0, read_noise=3.0, full_well=30000.0, black_level=64.0)
SIGNAL = 5000.0
TARGETS = {("dielectric", "eta"): (0.01, 0.03), ("dielectric", "alpha"): (0.03, 0.08),
           ("metal", "eta"): (0.03, 0.10), ("metal", "k"): (0.03, 0.10), ("metal", "alpha"): (0.03, 0.08)}
PULL_BAND = (0.8, 1.25)
CASES = ("dielectric", "metal", "metal_unpolarized")
CAMERAS = ("linear", "stokes")


def acquisition(case: str, camera: str, facet_angles=None):
    kind = "dielectric" if case == "dielectric" else "metal"
    kw = {} if facet_angles is None else {"facet_angles": facet_angles, "off_specular": ((35.0, 15.0),)}
    if case == "metal_unpolarized":
        kw.update(polarizer_angles=(None,), retarder=())
    return design_acquisition(kind, camera=camera, **kw)


def prepared(case: str, camera: str, *, n: int, res: int, spp_ref: int, facet_angles=None, seed: int = 0):
    """(truth, start, fit, observations) of one case seen by one camera (raw frames -> Stokes step)."""
    kind = "dielectric" if case == "dielectric" else "metal"
    truth = example_material(kind, n)
    truth["specular_reflectance"] = 1.0
    start = start_values(kind)
    obs = synthetic_observations(acquisition(case, camera, facet_angles), truth, start, res=res, spp=4,
                                 spp_ref=spp_ref, seed=seed, noise=NOISE, signal=SIGNAL)
    return truth, start, tuple(start), obs


def sigma_check(res: int, repeats: int = 100, seed: int = 5) -> dict:
    """Median over lit pixels of (std over ``repeats`` captures) / (mean propagated sigma), per camera
    and component, on the first dielectric picture (rendered once, noiseless at 64 spp)."""
    import mitsuba as mi

    from hyde_bsdf.inverse.acquisition import acquisition_scene_dict
    from hyde_bsdf.inverse.observations import render_stokes_np

    truth = example_material("dielectric", 4)
    truth["specular_reflectance"] = 1.0
    cfg = design_acquisition("dielectric").configurations[3]
    ref = render_stokes_np(mi.load_dict(acquisition_scene_dict(cfg, truth, res=res)), 0, 64, seed=seed)
    lit = ref[0] > 0.2 * np.median(ref[0][ref[0] > 0])
    rng = np.random.default_rng(seed)
    out = {}
    for camera in CAMERAS:
        runs = [simulate_capture(ref, NOISE, rng, camera=camera, signal=SIGNAL) for _ in range(repeats)]
        for c in runs[0].measured:
            scatter = np.std([r.stokes[c] for r in runs], axis=0)
            sigma = np.mean([r.sigma[c] for r in runs], axis=0)
            out[(camera, c)] = float(np.median(scatter[lit] / sigma[lit]))
    return out


def validate(outdir="out/validation", quick=False):
    import mitsuba as mi

    out = Path(outdir)
    out.mkdir(parents=True, exist_ok=True)
    previous = mi.variant()
    inv.prepare(inv.observations.MAP_VARIANT)
    if quick:
        obscfg = dict(n=4, res=16, spp_ref=32, facet_angles=(25.0, 55.0))
        fitcfg = dict(iterations=10, uncertainty_spp=4, polish=2, freeze=False)
        runs = [("dielectric", cam) for cam in CAMERAS]
    else:
        obscfg = dict(n=32, res=128, spp_ref=256)
        fitcfg = dict(iterations=60, uncertainty_spp=8, polish=3)
        runs = [(case, cam) for case in CASES for cam in CAMERAS]
    rows, stats, results, checks = [], {}, {}, []
    try:
        t0 = time.perf_counter()
        sig = sigma_check(16 if quick else 48, repeats=100)
        _log(f"sigma check ({time.perf_counter() - t0:.0f} s): "
                 + ", ".join(f"{k[0]} {k[1]} {v:.3f}" for k, v in sig.items()))
        for case, camera in runs:
            _log(f"{case}, {camera} camera ({obscfg['n']}x{obscfg['n']} maps)")
            results[(case, camera)] = run_case(case, "stokes", prepared(case, camera, **obscfg), **fitcfg)
            rows += _stats((case, camera), results[(case, camera)], stats)
            write_csv(out / "capture_camera.csv", CSV_HEADER[:1] + ["camera"] + CSV_HEADER[2:], rows)
        checks = _checks(stats, results, sig, quick)
        _plot(out / "capture_camera.png", stats, sig)
    finally:
        if previous is not None and previous != mi.variant():
            mi.set_variant(previous)
    return checks


def _checks(stats, results, sig, quick) -> list:
    checks = []
    for (camera, comp), ratio in sig.items():
        checks.append(dict(name=f"Stokes step sigma vs scatter of 100 captures, {camera} camera, {comp}",
                           value=f"{ratio:.3f}", passed=0.9 <= ratio <= 1.1))
    for (case, camera), (r, truth, msgs, secs) in results.items():
        for name in truth:
            st = stats[(case, camera, name)]
            if case == "metal_unpolarized" and name in ("eta", "k"):
                checks.append(dict(name=f"{case}, {camera}: {name} undetermined and warned", value=f"flagged "
                                   f"{100 * st['flagged']:.0f} % of texels", passed=st["warned"] and st["flagged"] > 0))
                continue
            target = TARGETS.get((case, name))
            if camera == "linear" and target and not quick:
                checks.append(dict(name=f"{case}, linear camera: {name} median | p90 |fit/truth - 1|",
                                   value=f"{100 * st['median']:.2f} % | {100 * st['p90']:.2f} % (<= "
                                   f"{100 * target[0]:g} | {100 * target[1]:g} %)",
                                   passed=st["median"] <= target[0] and st["p90"] <= target[1]))
            if not quick and case != "metal_unpolarized":
                checks.append(dict(name=f"{case}, {camera}: {name} pull std", value=f"{st['pull_std']:.3f}",
                                   passed=PULL_BAND[0] <= st["pull_std"] <= PULL_BAND[1]))
            if quick and name == "eta":
                checks.append(dict(name=f"{case}, {camera} camera (quick): eta median error", value=
                                   f"{100 * st['median']:.2f} %", passed=st["median"] < 0.05))
    for case in CASES:
        if (case, "linear") in results and (case, "stokes") in results:
            # per picture: the metal's linear design has 12 pictures, its full-Stokes one 9
            per = {cam: results[(case, cam)][0].seconds_per_iteration / len(acquisition(case, cam).configurations)
                   for cam in CAMERAS}
            ratio = per["linear"] / per["stokes"]
            checks.append(dict(name=f"{case}: time per iteration and picture, linear-only / full-Stokes input",
                               value=f"{ratio:.2f}", passed=quick or ratio <= 1.1))
    return checks


def _plot(path, stats, sig):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    keys = sorted({(c, n) for c, _, n in stats})
    fig, (ax, ax2) = plt.subplots(1, 2, figsize=(11, 4), gridspec_kw={"width_ratios": [3, 1]})
    x = np.arange(len(keys))
    for j, camera in enumerate(CAMERAS):
        med = [100 * stats.get((c, camera, n), {}).get("median", np.nan) for c, n in keys]
        p90 = [100 * stats.get((c, camera, n), {}).get("p90", np.nan) for c, n in keys]
        ax.bar(x + (j - 0.5) * 0.38, med, 0.38, label=f"{camera}: median", color=f"C{j}")
        ax.plot(x + (j - 0.5) * 0.38, p90, "v", color=f"C{j}", label=f"{camera}: 90th percentile")
    ax.set_xticks(x, [f"{c}\n{('n' if c.startswith('metal') and n == 'eta' else n)}" for c, n in keys], fontsize=7)
    ax.set_yscale("log")
    ax.set_ylabel("|fit / truth - 1| (%)")
    ax.set_title("per-texel error, linear-only (DoFP) vs full-Stokes camera", fontsize=9)
    ax.legend(fontsize=7)
    labels = [f"{cam[0]} {c}" for cam, c in sig]
    ax2.barh(np.arange(len(sig)), list(sig.values()), color="0.5")
    ax2.axvspan(0.9, 1.1, color="g", alpha=0.15)
    ax2.set_yticks(np.arange(len(sig)), labels, fontsize=7)
    ax2.set_xlim(0.7, 1.3)
    ax2.set_title("Stokes step: scatter / sigma", fontsize=9)
    fig.tight_layout()
    save_figure(fig, path)


if __name__ == "__main__":
    cli(validate, __doc__)
