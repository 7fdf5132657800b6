"""Model no more than a scene needs: what each simplification saves and what it costs.

For the scene of hyde_bsdf/validation/speed_accuracy_render.py (llvm variants, 64x40 px, 32 spp), each
choice is rendered both ways with the same seeds and compared with the Monte-Carlo noise of
that render (the standard error of the mean S0 per pixel, RMS over pixels, from 4 seeds):

1. polarized vs unpolarized variant (llvm_ad_spectral_polarized vs llvm_ad_spectral): the
   plugin computes only M00 in unpolarized variants; S0 differs only through polarization
   carried between bounces.
2. diffuse term on ("paper") vs off ("none"), at rms_slope 0.05, 0.15, 0.44, 1.0.
3. the plugin's DHR texture: fine (2049 x 640/decade, the default) vs coarse (129 x 20/decade).

Rule (documented in the README): a cheaper choice is the default wherever its image change is
below the Monte-Carlo noise of a typical render (here: 32 spp); otherwise the more complete
model stays the default.  Writes model_economy.png and .csv.
"""
import csv
import time
from pathlib import Path

import matplotlib
matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

from hyde_bsdf.io.atomic import atomic_open

from hyde_bsdf.validation._common import cli, save_figure  # noqa: E402

from hyde_bsdf.validation.speed_accuracy_render import SURFACES, scene_dict  # noqa: E402

SPP = 32
SEEDS = (11, 12, 13, 14)


def _s0(img, polarized):
    a = np.array(img)
    return a[..., 3:6].mean(-1) if polarized else a[..., :3].mean(-1)


def _renders(scene, polarized):
    """Mean S0 over SEEDS, its per-pixel standard error, and the median seconds per render."""
    import drjit as dr
    import mitsuba as mi
    imgs, secs = [], []
    mi.render(scene, spp=2, seed=1)      # compile
    for s in SEEDS:
        t0 = time.perf_counter()
        img = mi.render(scene, spp=SPP, seed=s)
        dr.eval(img)
        dr.sync_thread()
        secs.append(time.perf_counter() - t0)
        imgs.append(_s0(img, polarized))
    imgs = np.array(imgs)
    return imgs.mean(0), imgs.std(0, ddof=1) / np.sqrt(len(SEEDS)), float(np.median(secs))


def _compare(a, b):
    """RMS of the mean difference and the RMS Monte-Carlo noise of one SPP render (not the mean)."""
    (ma, sa, ta), (mb, _, tb) = a, b
    noise = float(np.sqrt(np.mean(sa ** 2) * len(SEEDS)))   # one render's noise
    diff = float(np.sqrt(np.mean((ma - mb) ** 2)))
    return diff, noise, tb / ta


def validate(outdir="out/validation", quick=False):
    import mitsuba as mi
    import hyde_bsdf
    from hyde_bsdf.mitsuba import plugin
    from hyde_bsdf.model import dhr
    from hyde_bsdf.model.terms import SHADOWING
    from hyde_bsdf.mitsuba.variants import set_variant
    out = Path(outdir)
    out.mkdir(parents=True, exist_ok=True)
    rows = []

    def load(polarized=True, **extra):
        set_variant("llvm_ad_spectral_polarized" if polarized else "llvm_ad_spectral", fallback=False)
        hyde_bsdf.register()
        d = scene_dict("hyde", **extra)
        if not polarized:
            d["integrator"] = d["integrator"]["integrator"]
        return mi.load_dict(d)

    # 1. unpolarized variant
    full = _renders(load(True), True)
    unpol = _renders(load(False), False)
    rows.append(["unpolarized variant (M00 path) vs polarized", "scene", *_compare(full, unpol)])
    # 2. diffuse term
    slopes = (0.05, 0.44) if quick else (0.05, 0.15, 0.44, 1.0)
    for s in slopes:
        surf = [(name, s, n, k) for name, _, n, k in SURFACES]
        with_d = _renders(load(True, surfaces=surf), True)
        without = _renders(load(True, surfaces=surf, diffuse="none"), True)
        rows.append(["diffuse none vs paper", s, *_compare(with_d, without)])
    # 3. DHR texture resolution
    saved = dict(dhr._TEXTURES)
    try:   # the shipped textures replaced by coarse ones resampled from the same tables
        for name in SHADOWING:
            dhr._TEXTURES[name] = dhr.texture_from_table(dhr.load_table(name), x_points=129, per_decade=20)
        plugin._DHR_CACHE.clear()
        coarse = _renders(load(True), True)
    finally:
        dhr._TEXTURES.clear()
        dhr._TEXTURES.update(saved)
        plugin._DHR_CACHE.clear()
    rows.append(["coarse DHR texture (129 x 20/decade) vs fine", "scene", *_compare(full, coarse)])

    fig, ax = plt.subplots(figsize=(8, 4))
    labels = [f"{r[0]}\n({r[1]})" for r in rows]
    x = np.arange(len(rows))
    ax.bar(x - 0.2, [r[2] for r in rows], 0.4, label="image change (RMS S0)")
    ax.bar(x + 0.2, [r[3] for r in rows], 0.4, label=f"MC noise of a {SPP}-spp render")
    for j, r in enumerate(rows):
        ax.text(x[j], max(r[2], r[3]) * 1.05, f"time x{r[4]:.2f}", ha="center", fontsize=7)
    ax.set_xticks(x, labels, fontsize=7)
    ax.set_ylabel("RMS over pixels")
    ax.legend(fontsize=8)
    ax.set_title("What each simplification changes, against Monte-Carlo noise (bars) and what it saves (time ratio)",
                 fontsize=9)
    fig.tight_layout()
    save_figure(fig, out / "model_economy.png", dpi=130)
    with atomic_open(out / "model_economy.csv", "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["simplification", "rms_slope", "rms_image_change", "rms_mc_noise", "time_ratio_simplified_over_full",
                    "below_noise"])
        for r in rows:
            w.writerow(r + [r[2] < r[3]])
    return [dict(name=f"economy: {r[0]} ({r[1]}): image change / MC noise (time ratio {r[4]:.2f})",
                 value=r[2] / r[3], tolerance="reported; < 1 means the cheaper model suffices", passed=True)
            for r in rows]


if __name__ == "__main__":
    cli(validate, __doc__)
