"""Capture at scale: time per iteration and peak memory of the per-texel inversion against texel count,
up to a 5-megapixel DoFP frame set (2448 x 2048 raw -> 1224 x 1024 Stokes super-pixels) mapped at 256 x 256
texels, in tiles (hyde_bsdf.inverse.tiles) on this machine.

The sample: ``hyde`` on a 2 x 2 plane with an n x n Beckmann-alpha map (nearest-neighbour texels; the
tutorial's gradient, eta 1.5), one calibrated camera (60 deg elevation, 3 units away, ``binning`` 2: the
intrinsics are the raw sensor's) and two point lights (docs/tutorials/camera.md's).  For each n the film
scales with the map -- (1224 x 1024) n / 256 super-pixels, a texel ~4.5 x 4.5 super-pixels at the
centre -- so 256^2 texels IS the 5-megapixel run.  The capture is simulated as in
hyde_bsdf/validation/capture_camera.py (its camera noise model NOISE and exposure SIGNAL): the truth rendered
through the calibrated sensor (2 passes of 4 spp), put on the raw DoFP mosaic (Sony layout) with shot
and read noise, and estimated back by super-pixel with propagated sigma
(:func:`hyde_bsdf.model.polarimetry.simulate_capture`).  Then :func:`invert_maps_tiled` fits alpha with
tiles of ~64 x 64 texels (``--tile-texels``), one after the other in the process
(:class:`~hyde_bsdf.mom.solver.SerialExecutor`), ``--iterations`` Adam iterations per tile at 4 spp
(the first two of each tile record the frozen step and are left out of the time per iteration), with
or without the uncertainty step (``--uncertainty``).

Each size runs in its own fresh process (its peak resident memory, ru_maxrss, is its own).  Reported per
size: the film, the tiles, the largest tile's film crops (pixels), the memory estimate checked before
the work (:func:`hyde_bsdf.resources.inversion_bytes`: largest tile x workers), the measured peak
RSS, seconds per iteration (all tiles together: the median over iterations 3.. of the tiles' summed
time of that iteration), the Adam loops' total (``loop_s``, all tiles, warm-up included), the rest of
the run (``rest_s``: scene builds, the uncertainty step), the whole run's wall time, the planning time
(pixels to tiles), the median |alpha / truth - 1| over the seen texels.
``--memory`` instead runs single tiles of growing film crops (no tiling) to check the estimate's
constants against the measured peak RSS.

    python benchmarks/bench_capture_scale.py [--sizes 32,64,128,256] [--iterations 8] [--uncertainty] [-o OUT]
    python benchmarks/bench_capture_scale.py --memory [--sizes 32,48,64]

Writes OUT.csv and OUT.png (time per iteration and peak memory against texel count).
"""
from __future__ import annotations

import argparse
import csv
import json
import math
import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent

FULL = (1224, 1024)          # Stokes super-pixels of the 5 MP DoFP camera (2448 x 2048 raw)
FULL_TEXELS = 256
LIGHTS = [{"type": "point", "position": [-2.5, 0.4, 2.5], "intensity": 20},
          {"type": "point", "position": [0.4, 2.5, 2.5], "intensity": 20}]
FIELDS = ("texels", "width", "height", "raw_megapixels", "tiles", "largest_tile_px", "estimate_gib", "peak_rss_gib",
          "seconds_per_iteration", "loop_s", "rest_s", "wall_s", "plan_s", "simulate_s", "median_alpha_error",
          "seen_texels", "iterations", "uncertainty")
#: iterations of each tile left out of the time per iteration: the first records the frozen step, the
#: second may record it again (dr.freeze makes literals that changed opaque and re-records once)
WARMUP = 2


def sample_xml(alpha_file) -> str:
    """The sample only (a textured hyde plane, the integrator): the calibration gives sensor and lights."""
    return f"""<scene version="3.0.0">
  <integrator type="stokes"><integrator type="path"><integer name="max_depth" value="2"/></integrator></integrator>
  <shape type="rectangle" id="plane">
    <bsdf type="hyde" id="sample">
      <texture type="bitmap" name="alpha">
        <string name="filename" value="{alpha_file}"/>
        <boolean name="raw" value="true"/>
        <string name="filter_type" value="nearest"/>
      </texture>
      <float name="eta" value="1.5"/>
    </bsdf>
  </shape>
</scene>"""


def camera_dict(n: int) -> dict:
    """The raw sensor's calibration for an n x n map: (2448 x 2048) n / 256 raw pixels, binning 2."""
    w, h = 2 * round(FULL[0] * n / FULL_TEXELS), 2 * round(FULL[1] * n / FULL_TEXELS)
    d = 3.0
    eye = np.array([d * math.cos(math.radians(60)), 0.0, d * math.sin(math.radians(60))])
    z = -eye / np.linalg.norm(eye)
    x = np.cross(z, [0.0, 0.0, 1.0])
    x /= np.linalg.norm(x)
    R = np.stack([x, np.cross(z, x), z])
    f = 0.95 * w * d / 2.0               # raw pixels: the plane's 2 units span ~95 % of the width
    return {"width": w, "height": h, "fx": f, "fy": f, "cx": w / 2 - 0.5, "cy": h / 2 - 0.5, "binning": 2,
            "R": R.tolist(), "t": (-R @ eye).tolist()}


def truth_map(n: int) -> np.ndarray:
    u = (np.arange(n) + 0.5) / n
    U, V = np.meshgrid(u, u)
    return 0.2 + 0.25 * U + 0.05 * np.sin(2 * np.pi * V)


def simulate(n: int, folder: Path, seed: int = 0):
    """The capture of an n x n sample: (Capture, truth, seconds)."""
    import mitsuba as mi

    from hyde_bsdf.validation.capture_camera import NOISE, SIGNAL
    from hyde_bsdf.model.polarimetry import simulate_capture
    from hyde_bsdf.inverse.camera_data import camera_reference
    from hyde_bsdf.inverse.observations import render_stokes_np
    from hyde_bsdf.inverse.tiles import Capture
    from hyde_bsdf.render.camera import Calibration, calibrated_scene, light_spec

    t0 = time.perf_counter()
    truth = truth_map(n)
    mi.Bitmap(truth.astype(np.float32)[..., None]).write(str(folder / "truth.exr"))
    mi.Bitmap(np.full((n, n, 1), 0.3, np.float32)).write(str(folder / "start.exr"))
    (folder / "truth.xml").write_text(sample_xml(folder / "truth.exr"))
    (folder / "sample.xml").write_text(sample_xml(folder / "start.exr"))
    cams = [Calibration.from_dict(camera_dict(n))]
    lights = [light_spec(x) for x in LIGHTS]
    rng = np.random.default_rng(seed)
    refs = []
    for j, light in enumerate(lights):
        scene = calibrated_scene(str(folder / "truth.xml"), cams, light, spp=4)
        S = np.mean([render_stokes_np(scene, 0, 4, seed=100 * j + k) for k in range(2)], axis=0)
        est = simulate_capture(S, NOISE, rng, camera="linear", signal=SIGNAL)
        refs.append((camera_reference(est),))
        del scene, S, est
    return Capture(str(folder / "sample.xml"), tuple(cams), tuple(lights), tuple(refs), spp=4), truth, \
        time.perf_counter() - t0


def child(n: int, tile_texels: int, iterations: int, uncertainty: bool) -> dict:
    """One size in this (fresh) process: simulate, plan, check the memory, invert in tiles."""
    import warnings

    from hyde_bsdf import inverse as inv
    from hyde_bsdf.inverse import tiles as tl

    inv.prepare(inv.observations.MAP_VARIANT)
    grid = max(1, round(n / tile_texels))
    with tempfile.TemporaryDirectory() as tmp:
        capture, truth, t_sim = simulate(n, Path(tmp))
        t0 = time.perf_counter()
        tasks, _, _ = tl.plan_tiles(capture, {"alpha": 0.3}, tiles=grid)
        t_plan = time.perf_counter() - t0
        largest = max(t.pixels for t in tasks)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            res = tl.invert_maps_tiled(capture, {"alpha": 0.3}, tiles=grid, iterations=iterations, spp=4,
                                       uncertainty=uncertainty,
                                       progress=lambda m: print(m, file=sys.stderr, flush=True))
    loop = [h["seconds"] for h in res.history]      # summed over the tiles: cumulative seconds per iteration
    seen = res.seen
    err = np.abs(res.final["alpha"] / truth - 1)[seen]
    w, h = capture.cameras[0].width, capture.cameras[0].height
    return {"texels": n, "width": w, "height": h, "raw_megapixels": round(4 * w * h / 1e6, 2),
            "tiles": f"{grid}x{grid}", "largest_tile_px": largest, "estimate_gib": round(res.memory_estimate / 2**30, 3),
            "peak_rss_gib": round(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 2**20, 3),
            "seconds_per_iteration": round(float(np.median(np.diff(loop)[WARMUP - 1:])), 3),
            "loop_s": round(loop[-1], 1), "rest_s": round(res.wall_seconds - loop[-1] - t_plan, 1),
            "wall_s": round(res.wall_seconds, 1),
            "plan_s": round(t_plan, 1), "simulate_s": round(t_sim, 1),
            "median_alpha_error": round(float(np.median(err)), 4), "seen_texels": int(seen.sum()),
            "iterations": iterations, "uncertainty": uncertainty}


def run_size(n, args) -> dict:
    cmd = [sys.executable, __file__, "--child", str(n), "--tile-texels", str(args.tile_texels),
           "--iterations", str(args.iterations)] + (["--uncertainty"] if args.uncertainty else [])
    env = {**os.environ, "PYTHONPATH": str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", "")}
    out = subprocess.run(cmd, capture_output=True, text=True, env=env)
    if out.returncode != 0:
        raise SystemExit(f"size {n} failed:\n{out.stderr[-3000:]}")
    return json.loads(out.stdout.strip().splitlines()[-1])


def plot(rows, path):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    x = [r["texels"] ** 2 for r in rows]
    fig, ax = plt.subplots(1, 2, figsize=(10, 4), layout="constrained")
    ax[0].loglog(x, [r["seconds_per_iteration"] for r in rows], "o-", label="s / iteration (all tiles)")
    ax[0].loglog(x, [r["wall_s"] for r in rows], "s--", label="wall time of the run (s)")
    ax[0].set_xlabel("texels")
    ax[0].set_title("time against texel count")
    ax[0].legend()
    ax[1].semilogx(x, [r["peak_rss_gib"] for r in rows], "o-", label="measured peak RSS")
    ax[1].semilogx(x, [r["estimate_gib"] for r in rows], "s--", label="estimate checked before the work")
    ax[1].set_xlabel("texels")
    ax[1].set_ylabel("GiB")
    ax[1].set_title("peak memory (tiles of ~64^2 texels, serial)")
    ax[1].legend()
    for r, xi in zip(rows, x):
        ax[1].annotate(f"{r['width']}x{r['height']}\n{r['tiles']}", (xi, r["peak_rss_gib"]), fontsize=7)
    fig.savefig(path, dpi=100)
    plt.close(fig)


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--sizes", default="32,64,128,256", help="texels per side, comma-separated")
    ap.add_argument("--tile-texels", type=int, default=64, help="texels per tile side (default 64)")
    ap.add_argument("--iterations", type=int, default=8, help="Adam iterations per tile (the first WARMUP=2 are "
                    "left out of the time per iteration)")
    ap.add_argument("--uncertainty", action="store_true", help="also the standard errors (invert_maps' defaults: 16 spp, "
                    "2 + up to 3 Gauss-Newton steps)")
    ap.add_argument("--memory", action="store_true", help="untiled single runs: the estimate against peak RSS")
    ap.add_argument("--child", type=int, default=None, help=argparse.SUPPRESS)
    ap.add_argument("-o", "--output", default="out/bench_capture_scale", help="output stem (.csv, .png)")
    args = ap.parse_args()
    if args.child is not None:
        print(json.dumps(child(args.child, args.tile_texels, args.iterations, args.uncertainty)))
        return
    if args.memory:
        args.tile_texels = 10**6                      # one tile: the whole picture
    rows = []
    for n in (int(s) for s in args.sizes.split(",")):
        rows.append(run_size(n, args))
        print(json.dumps(rows[-1]), flush=True)
    stem = Path(args.output + ("_memory" if args.memory else ""))
    stem.parent.mkdir(parents=True, exist_ok=True)
    with open(stem.with_suffix(".csv"), "w", newline="") as fh:
        w = csv.DictWriter(fh, FIELDS)
        w.writeheader()
        w.writerows(rows)
    plot(rows, stem.with_suffix(".png"))
    print(f"wrote {stem.with_suffix('.csv')} and {stem.with_suffix('.png')}")


if __name__ == "__main__":
    main()
