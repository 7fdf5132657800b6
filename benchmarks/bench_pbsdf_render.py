"""Render cost of a `hyde` material exported as a `measured_polarized` table, in any variant.

A gold sphere (rms_slope 0.3) under a sun and a dim sky, `stokes` integrator around `direct` or
`path`, rendered in one process with the material as Mitsuba's roughconductor (Beckmann, Au), the
Python `hyde` plugin, and the table written by `hyde-bsdf export` (resolution as given).  Prints
the first render of each (in LLVM/CUDA variants: the kernel compilation) and the median of
interleaved steady rounds, with the ratios to roughconductor; writes a CSV (``-o``).

    python benchmarks/bench_pbsdf_render.py [--variant llvm_ad_spectral_polarized] [--integrator direct]
                                            [--width 64 --height 48] [--spp 16] [--repeats 3]
                                            [--resolution 37x55x55] [-o out/bench/bench_pbsdf_render.csv]

The measured_polarized eval runs its 4-parameter table lookup once per Mueller element and
wavelength sample (64 lookups per call), all inlined into one kernel: in LLVM variants the first
render compiles that kernel (Dr.Jit caches it on disk for the next run).
"""
from __future__ import annotations

import argparse
import csv
import statistics
import sys
import tempfile
import time
from pathlib import Path


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--variant", default="llvm_ad_spectral_polarized")
    ap.add_argument("--integrator", default="direct", choices=("direct", "path"))
    ap.add_argument("--width", type=int, default=64)
    ap.add_argument("--height", type=int, default=48)
    ap.add_argument("--spp", type=int, default=16)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--resolution", default="37x55x55")
    ap.add_argument("-o", "--output", default="out/bench/bench_pbsdf_render.csv")
    a = ap.parse_args(argv)

    import drjit as dr
    import mitsuba as mi
    import hyde_bsdf
    from hyde_bsdf.io.atomic import atomic_open
    from hyde_bsdf.io.output_gate import check_output_path
    from hyde_bsdf.fit import export_pbsdf
    from hyde_bsdf.mitsuba.variants import set_variant
    from hyde_bsdf.model.roughness import alpha_from_rms_slope

    out = check_output_path(a.output, "CSV (-o)")
    set_variant(a.variant, fallback=False)
    hyde_bsdf.register(a.variant)
    folder = Path(tempfile.mkdtemp(prefix="bench_pbsdf_"))
    table = folder / "gold.pbsdf"
    rep = export_pbsdf(table, rms_slope=0.3, material="Au", resolution=a.resolution, error_samples=0)
    print(f"table: {rep.resolution} ({rep.nbytes / 1e6:.0f} MB), alpha_sample {rep.alpha_sample:.3g}", flush=True)
    integ = {"type": a.integrator} if a.integrator == "direct" else {"type": "path", "max_depth": 3}
    T = mi.ScalarTransform4f

    def scene(bsdf):
        return mi.load_dict({
            "type": "scene", "integrator": {"type": "stokes", "integrator": integ},
            "sensor": {"type": "perspective", "fov": 30,
                       "to_world": T().look_at(origin=[0, -4.0, 2.2], target=[0, 0, 0.1], up=[0, 0, 1]),
                       "film": {"type": "hdrfilm", "width": a.width, "height": a.height, "pixel_format": "rgb"},
                       "sampler": {"type": "independent", "sample_count": a.spp}},
            "ball": {"type": "sphere", "radius": 0.9, "bsdf": bsdf},
            "sun": {"type": "directional", "direction": [0.5, 0.7, -0.55], "irradiance": {"type": "rgb", "value": 3.0}},
            "sky": {"type": "constant", "radiance": {"type": "rgb", "value": 0.15}}})

    scenes = {"roughconductor": scene({"type": "roughconductor", "distribution": "beckmann", "material": "Au",
                                       "alpha": alpha_from_rms_slope(0.3)}),
              "hyde (Python)": scene({"type": "hyde", "rms_slope": 0.3, "material": "Au"}),
              "measured_polarized": scene({"type": "measured_polarized", "filename": str(table),
                                           "alpha_sample": rep.alpha_sample})}

    def render(name, seed):
        t0 = time.perf_counter()
        img = mi.render(scenes[name], spp=a.spp, seed=seed)
        dr.eval(img)
        dr.sync_thread()
        return time.perf_counter() - t0

    first = {}
    for name in scenes:
        first[name] = render(name, 0)
        print(f"first render {name}: {first[name]:.1f} s", flush=True)
    times = {n: [] for n in scenes}
    for r in range(a.repeats):
        for name in scenes:
            times[name].append(render(name, 1 + r))
    ref = statistics.median(times["roughconductor"])
    rows = []
    print(f"\n{a.variant}, stokes+{a.integrator}, {a.width}x{a.height}, {a.spp} spp, {a.repeats} rounds")
    print(f"{'bsdf':22s} {'first (s)':>10s} {'median (s)':>11s} {'/ roughconductor':>17s}")
    for name in scenes:
        med = statistics.median(times[name])
        rows.append([name, a.variant, a.integrator, f"{first[name]:.2f}", f"{med:.4f}", f"{med / ref:.2f}"])
        print(f"{name:22s} {first[name]:10.1f} {med:11.3f} {med / ref:17.2f}")
    with atomic_open(out, "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["bsdf", "variant", "integrator", "first_render_s", "median_s", "ratio"])
        w.writerows(rows)
    table.unlink()
    folder.rmdir()
    return 0


if __name__ == "__main__":
    sys.exit(main())
