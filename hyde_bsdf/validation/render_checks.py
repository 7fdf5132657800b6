"""Rendered checks of the Mitsuba side against closed-form predictions.

1. **Plane check.**  A flat plane (one BSDF, normal +z) lit by one unpolarized
   directional light of irradiance E (on a surface facing it), seen by an
   orthographic camera from a direction (theta_r, phi).  Every pixel then sees

       S_pixel = F(theta_i, theta_r, phi) [:, 0] * cos(theta_i) * E      (paper Eq. 2)

   in the paper's Stokes basis of the reflected wave.  The rendered Stokes vector
   (Mitsuba's sensor basis, see :func:`hyde_bsdf.render.sensor_to_paper_rotation`)
   is rotated into that basis and compared per Stokes component and colour
   channel with the prediction of the NumPy evaluator ``hyde_bsdf.pbrdf``, within
   Monte-Carlo error (from the pixel-to-pixel spread: all pixels are i.i.d.
   estimates of the same value) plus the model tolerance (roughconductor uses a
   rational approximation of the Smith G1 that the evaluator computes exactly).
   The camera's up vector is turned by a different angle per view so that the
   sensor-to-paper rotation is exercised, not just the identity.

2. **White furnace.**  A sphere with a 100 % reflective index (n + ik = 0 + 1i:
   |r_s| = |r_p| = 1 at every angle, like a perfect conductor) inside a uniform
   environment of radiance 1, seen by an orthographic camera, path depth 16.
   A pixel at distance r from the centre sees the sphere at theta_o = asin(r).
   For the paper's model (diffuse="paper", Eq. 17) the outgoing radiance is

       L(theta_o) = rho^s(theta_o) + 1 - rho_avg

   (the specular lobe is reciprocal and integrates to rho^{s,PEC}(theta_o); the
   diffuse term depends on the *incident* angle only and integrates to
   1 - rho_avg, rho_avg = 2 int rho cos sin dtheta); so the sphere is ~1
   everywhere but not exactly -- the known deviation of the non-reciprocal
   Eq. 17.  With diffuse="reciprocal" it is exactly 1, with diffuse="none" (or
   roughconductor) it is rho^s(theta_o) < 1.

Usage::

    python hyde_bsdf/validation/render_checks.py [-o out/validation] [--bsdf hyde|roughconductor]
                                       [--variant V] [--spp N] [--quick]

Writes render_check_plane.{png,csv} and render_check_furnace.{png,csv}.
Angles are in degrees in the CSV files and on the command line, radians inside.
"""
from __future__ import annotations

import argparse
import csv
import math
import sys
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from hyde_bsdf.render import prepare_variant, render_stokes, rotate_stokes, sensor_to_paper_rotation
from hyde_bsdf.model.roughness import alpha_from_rms_slope
from hyde_bsdf.io.atomic import atomic_open

from hyde_bsdf.validation._common import cli, save_figure  # noqa: E402

DEFAULT_VARIANT = "llvm_ad_spectral_polarized"

#: Plane-check views: (theta_i, theta_r, phi, up_turn) in degrees; up_turn turns the
#: camera's up vector about the view axis (exercises the Stokes-basis rotation).
PLANE_VIEWS_DEG = [
    (30.0, 30.0, 180.0, 0.0),     # specular direction
    (45.0, 20.0, 180.0, 25.0),    # specular plane, off-peak
    (60.0, 55.0, 150.0, -40.0),   # out of plane: S2 != 0
    (40.0, 35.0, 120.0, 70.0),
    (50.0, 40.0, 225.0, 10.0),    # the mirror-image side (phi > pi)
    (25.0, 30.0, 60.0, 100.0),    # backscatter side
    (70.0, 65.0, 170.0, -15.0),   # near grazing: shadowing matters
    (35.0, 0.0, 180.0, 30.0),     # normal view: paper basis is the limit at fixed azimuth
]
#: Roughness values of the white-furnace check.
FURNACE_SLOPES = (0.2, 0.5, 1.0)

#: Quick subset for the test suite.
QUICK_VIEWS_DEG = [PLANE_VIEWS_DEG[2], PLANE_VIEWS_DEG[4], PLANE_VIEWS_DEG[6]]

#: Materials of the plane check: (label, n, k, rms_slope).  A dielectric (strong
#: linear polarization) and the paper's two metals (Figs. 8, 9 at 1064 nm).
PLANE_MATERIALS = [
    ("glass n=1.5", 1.5, 0.0, 0.30),
    ("gold (Fig. 8)", 0.285, 7.3523, 0.44),
    ("aluminium (Fig. 9)", 1.226, 10.413, 0.43),
]


@dataclass
class BSDFSpec:
    """One BSDF as both a Mitsuba dict and the matching ``hyde_bsdf.pbrdf`` arguments."""

    kind: str               # "hyde" or "roughconductor"
    rms_slope: float
    n: float
    k: float
    shadowing: str = "smith"  # hyde only; roughconductor is always Smith
    diffuse: str = "none"     # hyde only; roughconductor has none

    def mitsuba(self) -> dict:
        if self.kind == "roughconductor":
            return {"type": "roughconductor", "distribution": "beckmann",
                    "alpha": alpha_from_rms_slope(self.rms_slope), "eta": self.n, "k": self.k}
        if self.kind == "hyde":
            return {"type": "hyde", "rms_slope": self.rms_slope, "eta": self.n, "k": self.k,
                    "shadowing": self.shadowing, "diffuse": self.diffuse}
        raise ValueError(f"bsdf must be 'hyde' or 'roughconductor', got {self.kind!r}")

    def evaluator_kwargs(self) -> dict:
        shadowing = "smith" if self.kind == "roughconductor" else self.shadowing
        diffuse = "none" if self.kind == "roughconductor" else self.diffuse
        return {"rms_slope": self.rms_slope, "n": self.n, "k": self.k,
                "shadowing": shadowing, "diffuse": diffuse}

    def model_rtol(self) -> float:
        """Relative disagreement allowed on top of Monte-Carlo error.

        Mitsuba's Smith G1 is a rational approximation (< 0.35 % error per G1, so
        < 0.7 % on the product); the plugin's "smith" uses the same approximation.
        V-groove and "none" are exact in both; float32 leaves ~1e-5.  The diffuse
        term reads the DHR table through a texture (interpolation ~1e-4 absolute).
        """
        return 0.008 if (self.kind == "roughconductor" or self.shadowing == "smith") else 2e-3


def _unit(v):
    v = np.asarray(v, dtype=float)
    return v / np.linalg.norm(v)


def plane_geometry(theta_i, theta_r, phi, up_turn):
    """World vectors of a plane-check view (radians in).

    Returns (omega_i, omega_r, up): directions towards the source and the observer
    (paper: phi_i = 0) and the camera's up vector, which is the projection of +z
    (or +x for a normal view) onto the image plane turned by ``up_turn`` about omega_r.
    """
    omega_i = np.array([math.sin(theta_i), 0.0, math.cos(theta_i)])
    omega_r = np.array([math.sin(theta_r) * math.cos(phi), math.sin(theta_r) * math.sin(phi),
                        math.cos(theta_r)])
    ref = np.array([0.0, 0.0, 1.0]) if math.sin(theta_r) > 0.2 else np.array([1.0, 0.0, 0.0])
    u1 = _unit(ref - np.dot(ref, omega_r) * omega_r)
    u2 = np.cross(omega_r, u1)
    up = math.cos(up_turn) * u1 + math.sin(up_turn) * u2
    return omega_i, omega_r, up


def plane_scene(theta_i, theta_r, phi, up_turn, bsdf: dict, res=16, spp=32, irradiance=1.0):
    """Mitsuba scene dict of the plane check (current variant must be polarized)."""
    import mitsuba as mi

    omega_i, omega_r, up = plane_geometry(theta_i, theta_r, phi, up_turn)
    T = mi.ScalarTransform4f
    return {
        "type": "scene",
        "integrator": {"type": "stokes", "integrator": {"type": "path", "max_depth": 2}},
        "sensor": {
            "type": "orthographic",
            # Looks at a 0.2 x 0.2 patch around the origin; the plane is much larger.
            "to_world": T().look_at(origin=(5.0 * omega_r).tolist(), target=[0, 0, 0], up=up.tolist())
            @ T().scale([0.1, 0.1, 1.0]),
            "film": {"type": "hdrfilm", "width": res, "height": res, "rfilter": {"type": "box"},
                     "sample_border": False},
            "sampler": {"type": "independent", "sample_count": spp},
        },
        "plane": {"type": "rectangle", "to_world": T().scale(50.0), "bsdf": bsdf},
        "light": {"type": "directional", "direction": (-omega_i).tolist(),
                  "irradiance": {"type": "rgb", "value": float(irradiance)}},
    }


def predict_plane(theta_i, theta_r, phi, irradiance, evaluator_kwargs):
    """Predicted pixel Stokes vector (paper basis of the reflected wave), shape (4,).

    F[:, 0] * cos(theta_i) * E: the first Mueller column because the source is unpolarized.
    """
    from hyde_bsdf import pbrdf

    F = pbrdf(theta_i, theta_r, phi, **evaluator_kwargs)
    return F[:, 0] * math.cos(theta_i) * irradiance


def measure_plane(theta_i, theta_r, phi, up_turn, spec: BSDFSpec, res=16, spp=32, seed=0,
                  irradiance=1.0):
    """Render one plane view; return (mean, sem) of the pixel Stokes vectors in the paper basis.

    Both arrays have shape (4, 3): Stokes component x colour channel (R, G, B).
    The standard error is the pixel-to-pixel standard deviation / sqrt(pixels).
    """
    import mitsuba as mi

    scene = mi.load_dict(plane_scene(theta_i, theta_r, phi, up_turn, spec.mitsuba(), res, spp,
                                     irradiance))
    out = render_stokes(scene, spp=spp, seed=seed, chunks=1, progress=False)
    _, omega_r, up = plane_geometry(theta_i, theta_r, phi, up_turn)
    angle = sensor_to_paper_rotation(-omega_r, up, phi_r=phi)
    s0, s1, s2, s3 = (out[s].reshape(-1, 3).astype(np.float64) for s in ("S0", "S1", "S2", "S3"))
    s1, s2 = rotate_stokes(s1, s2, angle)
    stack = np.stack([s0, s1, s2, s3])                     # (4, pixels, 3)
    npix = stack.shape[1]
    return stack.mean(axis=1), stack.std(axis=1, ddof=1) / math.sqrt(npix)


def run_plane_check(kind="roughconductor", views=PLANE_VIEWS_DEG, materials=PLANE_MATERIALS,
                    res=16, spp=32, seed=0, shadowing="smith", diffuse="none", nsigma=4.0,
                    progress=True):
    """Plane check over views x materials; returns a list of row dicts (one per view,
    material, Stokes component, colour channel) with 'pass' booleans."""
    rows = []
    total = len(views) * len(materials)
    count = 0
    t0 = time.perf_counter()
    for label, n, k, rms in materials:
        spec = BSDFSpec(kind, rms, n, k, shadowing, diffuse)
        for ti_d, tr_d, ph_d, up_d in views:
            ti, tr, ph, up = map(math.radians, (ti_d, tr_d, ph_d, up_d))
            pred = predict_plane(ti, tr, ph, 1.0, spec.evaluator_kwargs())
            mean, sem = measure_plane(ti, tr, ph, up, spec, res, spp, seed)
            tol_model = spec.model_rtol() * np.abs(pred) + 1e-6 * abs(pred[0])
            for c in range(4):
                for j, ch in enumerate("RGB"):
                    diff = mean[c, j] - pred[c]
                    allowed = nsigma * sem[c, j] + tol_model[c]
                    rows.append({
                        "bsdf": kind, "material": label, "n": n, "k": k, "rms_slope": rms,
                        "shadowing": spec.evaluator_kwargs()["shadowing"],
                        "diffuse": spec.evaluator_kwargs()["diffuse"],
                        "theta_i_deg": ti_d, "theta_r_deg": tr_d, "phi_deg": ph_d, "up_turn_deg": up_d,
                        "component": f"S{c}", "channel": ch, "predicted": float(pred[c]),
                        "rendered": float(mean[c, j]), "mc_sem": float(sem[c, j]),
                        "diff": float(diff), "allowed": float(allowed),
                        "z": float(diff / sem[c, j]) if sem[c, j] > 0 else float("nan"),
                        "pass": bool(abs(diff) <= allowed),
                    })
            count += 1
            if progress:
                print(f"\r[plane check] {count}/{total} views rendered, {time.perf_counter() - t0:5.1f} s",
                      end="\n" if count == total else "", file=sys.stderr, flush=True)
    return rows


# ---------------------------------------------------------------------------------------
# White furnace


def furnace_scene(bsdf: dict, res=64, spp=64, max_depth=16):
    """Unit sphere in a uniform environment of radiance 1 (rgb), orthographic view of [-1.1, 1.1]^2."""
    import mitsuba as mi

    T = mi.ScalarTransform4f
    return {
        "type": "scene",
        "integrator": {"type": "stokes", "integrator": {"type": "path", "max_depth": max_depth}},
        "sensor": {
            "type": "orthographic",
            "to_world": T().look_at(origin=[0, 0, 5], target=[0, 0, 0], up=[0, 1, 0])
            @ T().scale([1.1, 1.1, 1.0]),
            "film": {"type": "hdrfilm", "width": res, "height": res, "rfilter": {"type": "box"},
                     "sample_border": False},
            "sampler": {"type": "independent", "sample_count": spp},
        },
        "sphere": {"type": "sphere", "radius": 1.0, "bsdf": bsdf},
        "env": {"type": "constant", "radiance": {"type": "rgb", "value": 1.0}},
    }


def furnace_prediction(theta_o, rms_slope, shadowing, diffuse):
    """Predicted furnace radiance at viewing angle theta_o (radians) for an albedo-1 index.

    rho^s(theta_o) + [1 - rho_avg] (paper), 1 (reciprocal), rho^s(theta_o) (none);
    rho^s = rho^{s,PEC} of the chosen shadowing from ``hyde_bsdf.model.dhr.load_table``.
    """
    from hyde_bsdf.model.dhr import load_table

    table = load_table(shadowing)
    rho = table(theta_o, rms_slope)
    if diffuse == "paper":
        return rho + 1.0 - float(table.average(rms_slope))
    if diffuse == "reciprocal":
        return np.ones_like(rho)
    return rho


def run_furnace_check(kind="hyde", rms_slope=0.5, shadowing="vgroove", diffuse="paper", res=64,
                      spp=64, seed=0, nbins=12, rim=0.95, nsigma=4.0, model_atol=3e-3,
                      progress=True):
    """Render the furnace and compare ring averages with :func:`furnace_prediction`.

    Returns (rows, images): one row per ring of viewing angle (pixels with r < rim
    only: rim pixels straddle the silhouette), and a dict with the rendered S0 (R,G,B
    mean), the predicted map and the background level.
    """
    import mitsuba as mi

    if kind == "hyde":
        bsdf = {"type": "hyde", "rms_slope": rms_slope, "eta": 0.0, "k": 1.0,
                "shadowing": shadowing, "diffuse": diffuse}
    elif kind == "roughconductor":
        bsdf = {"type": "roughconductor", "distribution": "beckmann",
                "alpha": alpha_from_rms_slope(rms_slope), "eta": 0.0, "k": 1.0}
        shadowing, diffuse = "smith", "none"
    else:
        raise ValueError(f"bsdf must be 'hyde' or 'roughconductor', got {kind!r}")
    scene = mi.load_dict(furnace_scene(bsdf, res, spp))
    out = render_stokes(scene, spp=spp, seed=seed, chunks=min(spp, 16), progress=progress)
    img = out["S0"].astype(np.float64).mean(axis=-1)       # RGB average of S0
    sem = np.sqrt((out["S0_sem"].astype(np.float64) ** 2).mean(axis=-1) / 3.0)
    # Pixel centres in the sphere's projected disk (film spans [-1.1, 1.1]).
    c = (np.arange(res) + 0.5) / res * 2.2 - 1.1
    X, Y = np.meshgrid(c, c)
    r = np.hypot(X, Y)
    inside = r < rim
    background = float(img[r > 1.1 * 1.02].mean()) if np.any(r > 1.1 * 1.02) else float("nan")
    theta = np.arcsin(np.minimum(r, 1.0))
    pred_map = np.where(r < 1.0, furnace_prediction(theta, rms_slope, shadowing, diffuse), np.nan)
    edges = np.arcsin(np.linspace(0.0, rim, nbins + 1))
    rows = []
    for b in range(nbins):
        sel = inside & (theta >= edges[b]) & (theta < edges[b + 1])
        if not np.any(sel):
            continue
        m = float(img[sel].mean())
        e = float(np.sqrt((sem[sel] ** 2).sum()) / sel.sum())
        p = float(pred_map[sel].mean())
        rows.append({"bsdf": kind, "shadowing": shadowing, "diffuse": diffuse, "rms_slope": rms_slope,
                     "theta_lo_deg": math.degrees(edges[b]), "theta_hi_deg": math.degrees(edges[b + 1]),
                     "pixels": int(sel.sum()), "rendered": m, "mc_sem": e, "predicted": p,
                     "diff": m - p, "pass": bool(abs(m - p) <= nsigma * e + model_atol)})
    images = {"rendered": img, "predicted": pred_map, "background": background, "r": r,
              "theta": theta, "inside": inside}
    return rows, images


# ---------------------------------------------------------------------------------------
# Output


def write_csv(path: Path, rows: list[dict]) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    with atomic_open(path, "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=list(rows[0].keys()))
        w.writeheader()
        for row in rows:
            w.writerow({k: (f"{v:.7g}" if isinstance(v, float) else v) for k, v in row.items()})


def plot_plane(rows: list[dict], path: Path, title: str) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 4, figsize=(15, 4.6))
    for c, ax in enumerate(axes):
        sel = [r for r in rows if r["component"] == f"S{c}" and r["channel"] == "G"]
        x = np.array([r["predicted"] for r in sel])
        y = np.array([r["rendered"] for r in sel])
        e = np.array([r["mc_sem"] for r in sel])
        ok = np.array([r["pass"] for r in sel])
        lim = max(np.abs(np.concatenate([x, y])).max() * 1.1, 1e-4)
        ax.plot([-lim, lim], [-lim, lim], color="0.7", lw=1)
        ax.errorbar(x[ok], y[ok], yerr=4 * e[ok], fmt="o", ms=4, color="C0", label="pass")
        if np.any(~ok):
            ax.errorbar(x[~ok], y[~ok], yerr=4 * e[~ok], fmt="x", ms=6, color="C3", label="FAIL")
        ax.set_xlim(-lim if c else 0, lim)
        ax.set_ylim(-lim if c else 0, lim)
        ax.set_xlabel(f"predicted S{c} (pbrdf, paper basis)")
        ax.set_ylabel(f"rendered S{c} (G channel, rotated)")
        ax.set_title(f"S{c}: {ok.sum()}/{ok.size} within 4 sigma + model tol", fontsize=9)
        ax.legend(fontsize=8)
    fig.suptitle(title, fontsize=10)
    # the margins tight_layout chose for these labels, fixed: it measured every tick label again (~0.1 CPU s)
    fig.subplots_adjust(left=0.044, right=0.971, bottom=0.127, top=0.818, wspace=0.486)
    save_figure(fig, path, dpi=110)


def plot_furnace(rows: list[dict], images: dict, path: Path, title: str) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 3, figsize=(15, 4.4))
    pred = images["predicted"][np.isfinite(images["predicted"])]
    vmin, vmax = min(0.8, float(pred.min()) - 0.02), max(1.2, float(pred.max()) + 0.02)
    for ax, key, name in ((axes[0], "rendered", "rendered S0"), (axes[1], "predicted", "predicted")):
        im = ax.imshow(images[key], vmin=vmin, vmax=vmax, cmap="viridis")
        ax.set_title(name, fontsize=10)
        ax.set_xticks([])
        ax.set_yticks([])
        fig.colorbar(im, ax=ax, fraction=0.046)
    ax = axes[2]
    inside = images["inside"]
    th = np.degrees(images["theta"][inside])
    ax.plot(th, images["rendered"][inside], ".", ms=2, color="0.6", label="pixels")
    mid = [(r["theta_lo_deg"] + r["theta_hi_deg"]) / 2 for r in rows]
    ax.errorbar(mid, [r["rendered"] for r in rows], yerr=[4 * r["mc_sem"] for r in rows], fmt="o",
                color="C0", label="ring mean (4 sigma)")
    ax.plot(mid, [r["predicted"] for r in rows], "-", color="C3", label="prediction")
    ax.axhline(1.0, color="k", lw=0.8, ls=":")
    ax.set_xlabel("viewing angle theta_o (deg)")
    ax.set_ylabel("radiance / environment radiance")
    ax.set_title(f"background (environment) = {images['background']:.4f}", fontsize=9)
    ax.legend(fontsize=8)
    fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    save_figure(fig, path, dpi=110)


def _summary_plane(rows):
    """One line: passes, the worst |diff| / allowed, worst relative S0 error, and the
    largest |z| among components that are not ~0 (|predicted| > 1e-3 S0)."""
    fails = [r for r in rows if not r["pass"]]
    worst = max(abs(r["diff"]) / r["allowed"] for r in rows)
    s0 = {(r["material"], r["theta_i_deg"], r["theta_r_deg"], r["phi_deg"]): r["predicted"]
          for r in rows if r["component"] == "S0"}
    zs = np.array([abs(r["z"]) for r in rows if np.isfinite(r["z"]) and abs(r["predicted"]) >
                   1e-3 * s0[(r["material"], r["theta_i_deg"], r["theta_r_deg"], r["phi_deg"])]])
    rel = np.array([abs(r["diff"]) / r["predicted"] for r in rows if r["component"] == "S0"])
    return (f"{len(rows) - len(fails)}/{len(rows)} (view, material, component, channel) pass; "
            f"worst |diff|/allowed = {worst:.2f}, max |rel. S0 diff| = {rel.max():.2e}, "
            f"max |z| (non-zero components) = {zs.max() if zs.size else float('nan'):.1f}")


def validate(outdir="out/validation", quick=False, bsdf="hyde", variant=DEFAULT_VARIANT, spp=64, furnace_spp=256):
    """Run both checks; return the report's list of checks (name, value, tolerance, passed)."""
    out = Path(outdir)
    out.mkdir(parents=True, exist_ok=True)
    variant = prepare_variant(variant)
    print(f"[render_checks] variant {variant}, bsdf {bsdf}", file=sys.stderr)
    views = QUICK_VIEWS_DEG if quick else PLANE_VIEWS_DEG
    spp = 16 if quick else spp
    checks = []

    plane_sets = [("smith", "none")]
    if bsdf == "hyde":
        plane_sets += [("vgroove", "paper"), ("vgroove", "reciprocal")]
    all_rows = []
    for shadowing, diffuse in plane_sets:
        rows = run_plane_check(bsdf, views, PLANE_MATERIALS, res=16, spp=spp,
                               shadowing=shadowing, diffuse=diffuse)
        print(f"[plane check] {bsdf} shadowing={shadowing} diffuse={diffuse}: {_summary_plane(rows)}")
        n_pass = sum(r["pass"] for r in rows)
        checks.append(dict(name=f"plane check vs closed form ({bsdf}, {shadowing}, diffuse {diffuse}, {spp} spp): "
                                f"(view, material, Stokes component, channel) within MC error + model tol",
                           value=f"{n_pass}/{len(rows)}", tolerance="all", passed=n_pass == len(rows)))
        all_rows += rows
    write_csv(out / "render_check_plane.csv", all_rows)
    plot_plane(all_rows, out / "render_check_plane.png",
               f"Plane check ({bsdf}, {variant}, {spp} spp, 16x16 px per view, "
               f"{len(plane_sets)} shadowing/diffuse settings x 3 materials x {len(views)} views)\n"
               f"{_summary_plane(all_rows)}")

    fspp = 32 if quick else furnace_spp
    furnace_sets = ([("vgroove", "paper"), ("vgroove", "reciprocal")] if bsdf == "hyde"
                    else [("smith", "none")])
    frows_all = []
    for rms in (FURNACE_SLOPES[:1] if quick else FURNACE_SLOPES):
        for shadowing, diffuse in furnace_sets:
            frows, images = run_furnace_check(bsdf, rms_slope=rms, shadowing=shadowing,
                                              diffuse=diffuse, res=64, spp=fspp, progress=False)
            dev = max(abs(r["diff"]) for r in frows)
            lo = min(r["rendered"] for r in frows)
            hi = max(r["rendered"] for r in frows)
            print(f"[furnace] {bsdf} rms_slope={rms} shadowing={shadowing} diffuse={diffuse}: "
                  f"ring means in [{lo:.4f}, {hi:.4f}], max |rendered - predicted| = {dev:.4f}, "
                  f"background {images['background']:.4f}, "
                  f"{sum(r['pass'] for r in frows)}/{len(frows)} rings pass")
            n_pass = sum(r["pass"] for r in frows)
            checks.append(dict(name=f"white furnace, albedo-1 sphere ({bsdf}, rms_slope {rms}, {shadowing}, "
                                    f"diffuse {diffuse}, {fspp} spp): max |rendered - predicted| over rings",
                               value=float(dev), tolerance=f"{n_pass}/{len(frows)} rings within MC error",
                               passed=n_pass == len(frows)))
            frows_all += frows
            plot_furnace(frows, images, out / f"render_check_furnace_{diffuse}_rms{rms:g}.png",
                         f"White furnace: albedo-1 sphere (n+ik = i), rms_slope {rms:g}, {bsdf} "
                         f"shadowing={shadowing} diffuse={diffuse}, {fspp} spp, {variant}")
    write_csv(out / "render_check_furnace.csv", frows_all)
    print(f"[render_checks] wrote {out}/render_check_plane.{{png,csv}}, render_check_furnace*.png/.csv")
    return checks


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("-o", "--outdir", default="out/validation", help="output folder (default out/validation)")
    p.add_argument("--bsdf", choices=("hyde", "roughconductor"), default="hyde")
    p.add_argument("--variant", default=DEFAULT_VARIANT)
    p.add_argument("--spp", type=int, default=64, help="plane-check spp per pixel (default 64)")
    p.add_argument("--furnace-spp", type=int, default=256, help="furnace spp (default 256)")
    p.add_argument("--quick", action="store_true", help="fewer views, fewer samples")
    args = p.parse_args(argv)
    checks = validate(args.outdir, args.quick, args.bsdf, args.variant, args.spp, args.furnace_spp)
    return 0 if all(c["passed"] for c in checks) else 1


if __name__ == "__main__":
    cli(validate, __doc__, main)
