"""Measured agreement figures of the ``hyde`` plugin (the numbers quoted in the README).

Run ``python hyde_bsdf/validation/plugin_report.py [-o OUTDIR] [--quick]``.  It prints, and
writes as CSV into OUTDIR (default ``out/validation/``):

* ``plugin_vs_evaluator.csv`` - max over 10^4 random direction pairs of
  |F_plugin - F_eval| / (max|F_eval| + 1e-7 sr^-1), per (index, shadowing, diffuse),
  in llvm_ad_spectral_polarized (Mitsuba's Stokes bases rotated into the paper's);
* ``plugin_vs_roughconductor.csv`` - the same measure for eval, pdf and sample
  weights against Mitsuba's roughconductor (shadowing smith, diffuse none), and
  how many pairs exceed 1e-5 (all near backscatter, where roughconductor's own
  float32 frame is ill-conditioned);
* ``plugin_chi2.csv`` - chi^2 p-values of the sampling tests (the configurations of
  tests/test_plugin_sampling.py);
* ``plugin_dhr_texture.csv`` - max |(1 - rho) texture - (1 - rho) evaluator|.

Long work prints a progress line on stderr.
"""
from __future__ import annotations

import argparse
import csv
import math
import os
import sys

import numpy as np
from hyde_bsdf.io.atomic import atomic_open

__all__ = ["main", "cli_main"]

INDICES = {"Au": {"material": "Au"}, "glass": {"eta": 1.5, "k": 0.0},
           "large-k": {"eta": 1.2, "k": 10.4}}
WAVELENGTH = 633.0


def _progress(msg):
    print(f"\r[plugin_report] {msg:<70}", end="", file=sys.stderr, flush=True)


def _setup(variant):
    import mitsuba as mi
    from hyde_bsdf import register
    from hyde_bsdf.mitsuba.variants import set_variant

    set_variant(variant, fallback=False)
    register()
    return mi


def _index_at(mi, index):
    import drjit as dr

    b = mi.load_dict({"type": "hyde", "diffuse": "none", **index})
    si = dr.zeros(mi.SurfaceInteraction3f)
    si.wavelengths = mi.UnpolarizedSpectrum(WAVELENGTH)
    return (float(np.array(b.m_eta.eval(si)).ravel()[0]), float(np.array(b.m_k.eval(si)).ravel()[0]))


def vs_evaluator(n_dirs=10_000, seed=1):
    from hyde_bsdf import pbrdf
    from hyde_bsdf.validation import _frames as pf

    mi = _setup("llvm_ad_spectral_polarized")
    rng = np.random.default_rng(seed)
    ti, tr, ph, phi_i = pf.random_angles(n_dirs, rng)
    om_i, om_r, s_i, s_r = pf.paper_geometry(ti, tr, ph, phi_i)
    om_i = om_i.astype(np.float32).astype(float)
    om_r = om_r.astype(np.float32).astype(float)
    ti, tr, ph, _ = pf.angles_of(om_i, om_r)
    rows = []
    combos = [(lab, sh, df, rms) for lab in INDICES for sh in ("vgroove", "none", "smith")
              for df in ("none", "paper", "reciprocal") for rms in (0.1, 0.44, 1.0)
              if not (sh == "none" and df == "reciprocal")]
    for j, (lab, sh, df, rms) in enumerate(combos):
        _progress(f"evaluator {j + 1}/{len(combos)}")
        params = {"type": "hyde", "rms_slope": rms, "shadowing": sh, "diffuse": df, **INDICES[lab]}
        Fp = pf.eval_paper(mi.load_dict(params), om_i, om_r, s_i, s_r, wavelength=WAVELENGTH)
        n, k = _index_at(mi, INDICES[lab])
        Fe = pbrdf(ti, tr, ph, rms_slope=rms, n=n, k=k, shadowing=sh, diffuse=df)
        scale = np.abs(Fe).max(axis=(-2, -1), keepdims=True)
        rel = np.abs(Fp - Fe) / (scale + 1e-7)
        off = rel.copy()
        off[..., 0, 0] = 0.0
        rows.append({"index": lab, "n": f"{n:.4f}", "k": f"{k:.4f}", "shadowing": sh, "diffuse": df,
                     "rms_slope": rms, "pairs": n_dirs, "max_rel": f"{rel.max():.3e}",
                     "max_rel_excl_F00": f"{off.max():.3e}"})
    print(file=sys.stderr)
    return rows


def vs_roughconductor(n=10_000):
    import drjit as dr

    mi = _setup("llvm_ad_spectral_polarized")
    rows = []
    rng = np.random.default_rng(0)

    def hemi():
        z = rng.uniform(0.02, 1.0, n)
        p = rng.uniform(0, 2 * math.pi, n)
        r = np.sqrt(1 - z * z)
        return np.stack([r * np.cos(p), r * np.sin(p), z], -1).astype(np.float32)

    def mat(v):
        dr.eval(v)
        return np.stack([np.stack([np.array(v[r, c]).reshape(-1, n)[0] for c in range(4)], -1)
                         for r in range(4)], -2)

    def rel(a, b):
        s = np.abs(b).max(axis=(-2, -1), keepdims=True) if b.ndim == 3 else np.abs(b)
        e = np.abs(a - b) / (s + 1e-7)
        return e.reshape(len(e), -1).max(axis=1)

    for alpha, index, vis, mode in [(0.1, "Au", True, "radiance"), (0.42, "Al", True, "importance"),
                                    (0.8, "glass", False, "radiance"), (0.3, "Cu", False, "importance")]:
        idx = {"material": index} if index in ("Au", "Al", "Cu") else INDICES[index]
        h = mi.load_dict({"type": "hyde", "alpha": alpha, "shadowing": "smith", "diffuse": "none",
                          "sample_visible": vis, **idx})
        r = mi.load_dict({"type": "roughconductor", "alpha": alpha, "sample_visible": vis, **idx})
        wi, wo = hemi(), hemi()
        ctx = mi.BSDFContext(mi.TransportMode.Radiance if mode == "radiance" else mi.TransportMode.Importance)
        si = dr.zeros(mi.SurfaceInteraction3f)
        si.wi = mi.Vector3f(*(mi.Float(wi[:, j]) for j in range(3)))
        si.wavelengths = mi.UnpolarizedSpectrum(mi.Float(np.linspace(400, 700, n).astype(np.float32)))
        wov = mi.Vector3f(*(mi.Float(wo[:, j]) for j in range(3)))
        e_eval = rel(mat(h.eval(ctx, si, wov)), mat(r.eval(ctx, si, wov)))
        e_pdf = rel(np.array(h.pdf(ctx, si, wov)), np.array(r.pdf(ctx, si, wov)))
        s1 = mi.Float(rng.random(n).astype(np.float32))
        s2 = mi.Point2f(*(mi.Float(rng.random(n).astype(np.float32)) for _ in range(2)))
        (b1, w1), (b2, w2) = h.sample(ctx, si, s1, s2), r.sample(ctx, si, s1, s2)
        W1, W2 = mat(w1), mat(w2)
        ok = np.abs(W2[:, 0, 0]) > 0
        e_w = rel(W1[ok], W2[ok])
        e_spdf = rel(np.array(b1.pdf)[ok], np.array(b2.pdf)[ok])
        sin_io = np.linalg.norm(np.cross(wi.astype(float), wo.astype(float)), axis=-1)
        over = e_eval > 1e-5
        rows.append({"alpha": alpha, "index": index, "sample_visible": vis, "mode": mode, "pairs": n,
                     "eval_max_rel": f"{e_eval.max():.3e}", "eval_pairs_over_1e-5": int(over.sum()),
                     "max_sin_wi_wo_of_those": f"{sin_io[over].max():.2e}" if over.any() else "",
                     "pdf_max_rel": f"{e_pdf.max():.3e}", "sample_pdf_max_rel": f"{e_spdf.max():.3e}",
                     "sample_weight_max_rel": f"{e_w.max():.3e}"})
    return rows


def chi2_pvalues():
    from hyde_bsdf.validation._chi2 import chi2_test

    configs = [(0.02, 30), (0.02, 60), (0.05, 0), (0.05, 45), (0.1, 0), (0.1, 85), (0.3, 45),
               (0.3, 80), (0.6, 10), (0.6, 70), (1.0, 30), (1.5, 0), (1.5, 85)]
    models = {"llvm_ad_rgb": [("vgroove", "paper", True), ("smith", "none", True), ("none", "paper", True)],
              "llvm_ad_spectral_polarized": [("vgroove", "paper", True), ("vgroove", "reciprocal", False),
                                             ("smith", "paper", True)]}
    total = sum(len(m) for m in models.values()) * len(configs)
    rows = []
    for variant, ms in models.items():
        mi = _setup(variant)
        for sh, df, vis in ms:
            for rms, th in configs:
                _progress(f"chi2 {len(rows) + 1}/{total}")
                b = mi.load_dict({"type": "hyde", "rms_slope": rms, "material": "Au", "shadowing": sh,
                                  "diffuse": df, "sample_visible": vis})
                ok, p, _ = chi2_test(b, math.radians(th), sample_count=1_000_000, res=128, ires=8,
                                     test_count=total)
                rows.append({"variant": variant, "shadowing": sh, "diffuse": df, "sample_visible": vis,
                             "rms_slope": rms, "theta_i_deg": th, "p_value": f"{p:.4g}", "passed": ok})
    print(file=sys.stderr)
    return rows


def dhr_texture():
    from hyde_bsdf.model.evaluator import diffuse_pbrdf
    from hyde_bsdf.mitsuba.plugin import _dhr_lookup

    mi = _setup("llvm_ad_rgb")
    rng = np.random.default_rng(11)
    theta = np.arccos(rng.uniform(math.cos(math.radians(89.0)), 1.0, 20_000))
    from hyde_bsdf.model.dhr import load_table

    rows = []
    th2 = np.arccos(rng.uniform(math.cos(math.radians(89.0)), 1.0, 200_000))
    rms2 = np.exp(rng.uniform(math.log(0.02), math.log(1.5), th2.size))
    for sh in ("vgroove", "smith", "none"):
        lut = _dhr_lookup(sh)
        worst = 0.0
        for rms in (0.02, 0.05, 0.1, 0.2, 0.3, 0.44, 0.7, 1.0, 1.5):
            got = np.maximum(np.array(lut.one_minus_rho(mi.Float(np.cos(theta)),
                                                        lut.slope_coord(mi.Float(rms)))), 0.0)
            want = math.pi * diffuse_pbrdf(theta, theta, 1.0, rms, "paper", sh)
            worst = max(worst, float(np.abs(got - want).max()))
        # against the table's own __call__ (bicubic spline), 1 - rho clipped at 0 as used
        got = np.maximum(np.array(lut.one_minus_rho(mi.Float(np.cos(th2)), lut.slope_coord(mi.Float(rms2)))), 0)
        want = np.maximum(1.0 - load_table(sh)(th2, rms2), 0.0)
        rows.append({"shadowing": sh, "theta_max_deg": 89.0, "rms_slope_range": "0.02-1.5",
                     "max_abs_err_vs_evaluator": f"{worst:.2e}",
                     "max_abs_err_vs_table_call": f"{np.abs(got - want).max():.2e}"})
    return rows


def _write(outdir, name, rows):
    os.makedirs(outdir, exist_ok=True)
    path = os.path.join(outdir, name)
    with atomic_open(path, "w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=list(rows[0].keys()))
        w.writeheader()
        w.writerows(rows)
    return path


def _show(title, rows):
    print(f"\n## {title}")
    keys = list(rows[0].keys())
    print(" | ".join(keys))
    for r in rows:
        print(" | ".join(str(r[k]) for k in keys))


def cli_main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="python hyde_bsdf/validation/plugin_report.py", description=__doc__.split("\n")[0])
    ap.add_argument("-o", "--outdir", default=os.path.join("out", "validation"))
    ap.add_argument("--skip-chi2", action="store_true", help="leave out the chi^2 p-values (~30 s)")
    args = ap.parse_args(argv)
    parts = [("plugin_vs_evaluator.csv", "plugin vs NumPy evaluator", vs_evaluator),
             ("plugin_vs_roughconductor.csv", "plugin vs roughconductor", vs_roughconductor),
             ("plugin_dhr_texture.csv", "DHR texture vs evaluator lookup", dhr_texture)]
    if not args.skip_chi2:
        parts.append(("plugin_chi2.csv", "chi2 p-values", chi2_pvalues))
    for fname, title, fn in parts:
        rows = fn()
        _show(title, rows)
        if fname == "plugin_vs_evaluator.csv":
            spec = [float(r["max_rel"]) for r in rows if r["diffuse"] == "none" and r["shadowing"] != "smith"]
            diff = [float(r["max_rel"]) for r in rows if r["diffuse"] != "none" and r["shadowing"] != "smith"]
            smith = [float(r["max_rel"]) for r in rows if r["shadowing"] == "smith"]
            print(f"summary: specular-only max rel {max(spec):.2e}; with diffuse {max(diff):.2e}; "
                  f"smith (rational G1) {max(smith):.2e}")
        if fname == "plugin_chi2.csv":
            p = np.array([float(r["p_value"]) for r in rows])
            print(f"summary: {sum(r['passed'] for r in rows)}/{len(rows)} passed; p min {p.min():.3g}, "
                  f"median {np.median(p):.3g}")
        print("wrote", _write(args.outdir, fname, rows))
    return 0


def main():
    sys.exit(cli_main())


if __name__ == "__main__":
    main()
