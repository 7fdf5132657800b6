"""Are the evaluator's and the plugin's results bitwise those of another commit?  (issue 34: a redesign
keeps the results, or explains each change.)

    python tools/compare_outputs.py save OUT.npz      # with PYTHONPATH=<a checkout of the commit>
    python tools/compare_outputs.py compare A.npz B.npz

``save`` evaluates ``hyde_bsdf.pbrdf`` at 4000 random geometries (seed 5) for every shadowing x diffuse
pair, two indices and three roughnesses, and the plugin's ``eval`` and ``pdf`` (scalar_spectral_polarized,
rms_slope 0.3, n 0.27 + 3i, each shadowing, every parameter named: a default that changed on purpose
does not hide a formula that changed) at 200 of them; ``compare`` names every array that differs.
Measured 2026-12-03: 153e90e (before the term records, the index type, the shipped DHR tables) against
91bd817: all 49 arrays bitwise equal.
"""
import sys

import numpy as np


def save(out):
    import hyde_bsdf

    rng = np.random.default_rng(5)
    n = 4000
    ti, tr, phi = rng.uniform(0, 1.5, n), rng.uniform(0, 1.5, n), rng.uniform(0, 2 * np.pi, n)
    res = {}
    for sh in ("vgroove", "smith", "none"):
        for df in ("paper", "reciprocal", "none"):
            if df == "reciprocal" and sh == "none":
                continue
            for nn, kk in ((1.5, 0.0), (0.27, 3.0)):
                for s in (0.05, 0.3, 1.2):
                    res[f"ev_{sh}_{df}_{nn}_{s}"] = np.asarray(
                        hyde_bsdf.pbrdf(ti, tr, phi, n=nn, k=kk, rms_slope=s, shadowing=sh, diffuse=df))
    import mitsuba as mi

    mi.set_variant("scalar_spectral_polarized")
    hyde_bsdf.register("scalar_spectral_polarized")
    vals = []
    for sh in ("vgroove", "smith"):
        b = mi.load_dict({"type": "hyde", "rms_slope": 0.3, "eta": 0.27, "k": 3.0, "shadowing": sh,
                          "diffuse": "paper"})
        ctx = mi.BSDFContext()
        for i in range(200):
            si = mi.SurfaceInteraction3f()
            si.wavelengths = mi.UnpolarizedSpectrum([550, 600, 650, 700])
            si.wi = mi.Vector3f(np.sin(ti[i]), 0, np.cos(ti[i]))
            wo = mi.Vector3f(np.sin(tr[i]) * np.cos(phi[i]), np.sin(tr[i]) * np.sin(phi[i]), np.cos(tr[i]))
            vals.append(np.array(b.eval(ctx, si, wo), dtype=np.float64).ravel())
            vals.append(np.array([b.pdf(ctx, si, wo)], dtype=np.float64))
    res["plugin"] = np.concatenate(vals)
    np.savez(out, **res)
    print(f"saved {len(res)} arrays to {out}")


def compare(a_path, b_path):
    a, b = np.load(a_path), np.load(b_path)
    differ = 0
    for k in sorted(set(a.files) | set(b.files)):
        if k not in a.files or k not in b.files:
            print(f"{k}: only in one file")
            differ += 1
        elif a[k].shape != b[k].shape or not np.array_equal(a[k], b[k], equal_nan=True):
            x, y = a[k], b[k]
            rel = np.nanmax(np.abs(x - y) / np.maximum(np.abs(x), 1e-300)) if x.shape == y.shape else float("nan")
            print(f"{k}: differs (largest relative difference {rel:.3g})")
            differ += 1
    print(f"{len(a.files) - differ} of {len(a.files)} arrays bitwise equal")
    return 1 if differ else 0


if __name__ == "__main__":
    if len(sys.argv) == 3 and sys.argv[1] == "save":
        save(sys.argv[2])
    elif len(sys.argv) == 4 and sys.argv[1] == "compare":
        sys.exit(compare(sys.argv[2], sys.argv[3]))
    else:
        sys.exit(__doc__)
