"""Measure every entry of :data:`hyde_bsdf.resources.COSTS` and print it beside the table's value.

Memory: the peak resident size (ru_maxrss) of a fresh child process running the command the model
is for, at three sizes, against the table's estimate at that size; the line through the smallest
and largest size gives the fixed part and the cost per unit.  (Dr.Jit's allocator rounds blocks up
to powers of two, so the cost per unit steps between sizes: the model is a bound, not a fit.)
Times: CPU seconds on one core (single-threaded BLAS).  The last column, table / measured (for a
memory model: the estimate over the measured peak), should be >= 1; a cost that grew past its
entry shows < 1: raise the entry.  After a change that moves a cost, rerun and copy the figures
into ``hyde_bsdf/resources.py``.

    .venv/bin/python benchmarks/bench_resources.py [--only render,ad,forward,dense,fast,surface,stokes,pbrdf,csv,pbsdf]

Not measured here: ``map_bytes_per_texel_*`` (counted: float64 arrays) and ``plot_file_bytes``
(an upper bound; the plot ``invert`` writes is printed as a check).
"""
from __future__ import annotations

import argparse
import json
import math
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
CLI = [sys.executable, "-m", "hyde_bsdf.app.cli"]


def peak_rss(cmd) -> int:
    """Peak resident bytes of the child ``cmd`` (Linux reports ru_maxrss in KiB)."""
    proc = subprocess.Popen(cmd, cwd=ROOT, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    _, status, usage = os.wait4(proc.pid, 0)
    if status != 0:
        raise SystemExit(f"{' '.join(map(str, cmd))} failed: {proc.stderr.read()[-2000:]}")
    return usage.ru_maxrss * 1024


def memory_model(name, units, commands, estimate, fixed_key, per_key):
    """Rows of a memory model: the fixed part and the cost per unit through the smallest and largest
    size, and, per size, the measured peak against ``estimate(units)``."""
    rss = [peak_rss(cmd) for cmd in commands]
    per = (rss[-1] - rss[0]) / (units[-1] - units[0])
    rows = {fixed_key: rss[0] - per * units[0], per_key: per}
    rows.update({f"{name} at {u:.3g} (estimate/peak)": (r, estimate(u)) for u, r in zip(units, rss)})
    return rows


def render(tmp, variant, polarized):
    """``hyde-bsdf render hyde_bsdf/data/scenes/inverse.xml`` at res 300, 600 and 900, 1 spp."""
    from hyde_bsdf.resources import render_bytes

    sizes = (300, 600, 900)
    cmds = [CLI + ["render", "hyde_bsdf/data/scenes/inverse.xml", "-o", str(tmp / f"r{r}.exr"), "--variant", variant,
                   "-D", f"res={r}", "--spp", "1", "-q"] for r in sizes]
    per_key = "render_stokes_bytes_per_pixel" if polarized else "render_colour_bytes_per_pixel"
    return memory_model(f"render {variant} px", [r * r for r in sizes], cmds,
                        lambda px: render_bytes(px, 1, polarized), f"render_fixed_bytes ({variant})", per_key)


def ad(tmp):
    """Reverse mode: ``hyde-bsdf invert`` (the built-in scene, spectral) at 64^2, 128^2 and 192^2 px,
    16 spp, and ``invert --maps --no-uncertainty`` (the built-in plane, mono, every light) at 48^2,
    96^2 and 144^2 px per picture, 16 spp; the history CSV."""
    from hyde_bsdf.inverse.observations import LIGHTS
    from hyde_bsdf.resources import inversion_bytes

    sizes, spp = (64, 128, 192), 16
    cmds = [CLI + ["invert", "--res", str(r), "--spp", str(spp), "--spp-ref", "4", "--iterations", "2",
                   "-o", str(tmp / f"inv{r}"), "-q"] for r in sizes]
    rows = memory_model("invert samples", [r * r * spp for r in sizes], cmds,
                        lambda s: inversion_bytes(s, 1), "ad_fixed_bytes (spectral)",
                        "ad_bytes_per_sample (spectral)")
    sizes = (48, 96, 144)
    cmds = [CLI + ["invert", "--maps", "--map-size", "8", "--res", str(r), "--spp", str(spp), "--spp-ref", "4",
                   "--iterations", "2", "--no-uncertainty", "-o", str(tmp / f"mapsad{r}"), "-q"] for r in sizes]
    rows.update(memory_model("invert --maps samples", [len(LIGHTS) * r * r * spp for r in sizes], cmds,
                             lambda s: inversion_bytes(s, 1), "ad_fixed_bytes", "ad_bytes_per_sample"))
    history = tmp / "inv192" / "invert_history.csv"
    rows["history_row_bytes"] = history.stat().st_size / history.read_text().count("\n")
    rows["plot_file_bytes (invert's plot)"] = max(p.stat().st_size for p in (tmp / "inv192").glob("*.png"))
    return rows


def forward(tmp):
    """``hyde-bsdf invert --maps`` (the built-in plane, every light): 1 spp steps, so the uncertainty
    step's forward-mode renders at 16 spp set the peak; 48^2, 96^2 and 144^2 px per picture
    (samples counted over all pictures)."""
    from hyde_bsdf.inverse.observations import LIGHTS
    from hyde_bsdf.resources import inversion_bytes

    sizes, spp = (48, 96, 144), 16
    cmds = [CLI + ["invert", "--maps", "--map-size", "8", "--res", str(r), "--spp", "1", "--spp-ref", "4",
                   "--iterations", "2", "-o", str(tmp / f"maps{r}"), "-q"] for r in sizes]
    return memory_model("invert --maps forward samples", [len(LIGHTS) * r * r * spp for r in sizes], cmds,
                        lambda s: inversion_bytes(s, 0, 1), "ad_fixed_bytes (forward)",
                        "ad_forward_bytes_per_sample")


def dense():
    """Dense solves of a flat partition on one core: PEC s at 1000 and 3 x 2000 unknowns (fill per entry,
    LU per n^3: the least of the rounds, the least disturbed by other work), glass s+p at 1500 (the
    lossless interior's (1/2 + D1)^-1 S1 per n^3)."""
    import numpy as np

    from hyde_bsdf.mom.dense import solve_dense
    from hyde_bsdf.mom.runtime import limit_blas_threads

    limit_blas_threads(1)

    def solve(n, pols, eta):
        x = (np.arange(n) + 0.5) / 10.0
        zero = np.zeros(n)
        psi = np.exp(1j * 2 * np.pi * x * 0.5)[:, None]
        return solve_dense(x, zero, zero, zero, 0.1, psi, pols, eta, time.process_time)["times"]

    fill, lu = [], []
    for n in (1000, 2000, 2000, 2000):
        t = solve(n, ("s",), None)
        fill.append(t[0] / n**2)
        lu.append(t[1] / n**3)
    n = 1500
    t = solve(n, ("s", "p"), 1.5 + 0j)
    per_entry = min(fill)
    return {"dense_fill_seconds_per_entry": per_entry, "dense_lu_seconds_per_n3": min(lu),
            "dense_interior_seconds_per_n3": (t[0] - 2 * per_entry * n * n) / n**3}


def fast():
    """The fast solver's worst case the entry stands for: one glass partition of issue 25's grazing run
    (966 wavelengths at 8 points: 7728 unknowns, sigma_h = 2, ell = 14.1, n = 1.5, theta_i = 85 deg),
    s and p: CPU seconds per unknown."""
    import warnings

    from hyde_bsdf import mom
    from hyde_bsdf.mom.runtime import limit_blas_threads
    from hyde_bsdf.mom.solver import SerialExecutor

    limit_blas_threads(1)
    t0 = time.process_time()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        mom.scatter(966.0, 1, 2.0, 14.1, [85.0], [85.0], pts_per_wl=8, solver="fast", n=1.5, k=0.0,
                    polarization=("s", "p"), executor=SerialExecutor(), progress=False)
    return {"fast_seconds_per_unknown": (time.process_time() - t0) / 7728}


def surface():
    """Peak bytes per point of drawing a surface with its derivatives (tracemalloc, 2^20 points)."""
    import tracemalloc

    from hyde_bsdf.mom.solver import gaussian_surface

    points = 2**20
    tracemalloc.start()
    gaussian_surface(points / 10.0, points, 0.5, 3.0, 0, second_derivative=True)
    peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    return {"surface_bytes_per_point": peak / points}


def stokes():
    """Peak bytes per raw value of the Stokes step (tracemalloc): 4 frames of 1000x1000 through the
    least squares, and a 2000x2000 mosaic demosaicked superpixel and bilinear."""
    import tracemalloc

    import numpy as np

    from hyde_bsdf.model.polarimetry import CameraNoise, stokes_from_frames, stokes_from_mosaic

    rng, noise = np.random.default_rng(0), CameraNoise(read_noise=2.0, black_level=64.0)
    out = {}
    for key, values, run in (
            ("stokes_bytes_per_value", 4 * 10**6,
             lambda raw: stokes_from_frames(list(raw.reshape(4, 1000, 1000)), [0.0, 45.0, 90.0, 135.0], noise=noise)),
            ("stokes_bytes_per_value (mosaic, superpixel)", 4 * 10**6,
             lambda raw: stokes_from_mosaic(raw.reshape(2000, 2000), noise=noise)),
            ("stokes_bilinear_bytes_per_value", 4 * 10**6,
             lambda raw: stokes_from_mosaic(raw.reshape(2000, 2000), method="bilinear", noise=noise))):
        raw = rng.uniform(500.0, 3000.0, values).round()
        tracemalloc.start()
        run(raw)
        peak = tracemalloc.get_traced_memory()[1]
        tracemalloc.stop()
        out[key] = peak / values
    return out


def pbrdf():
    """Peak bytes per direction of the evaluator beyond its inputs (tracemalloc, 10^6 directions)."""
    import tracemalloc

    import numpy as np

    from hyde_bsdf import pbrdf as evaluate

    rng = np.random.default_rng(0)
    ti, tr, ph = rng.uniform(0.0, 1.5, (3, 10**6))
    tracemalloc.start()
    evaluate(ti, tr, ph, rms_slope=0.3, n=1.5)
    peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    return {"pbrdf_bytes_per_direction": peak / ti.size}


def csv(tmp):
    """Peak bytes per value (one per comma or line end) while ``read_measurements`` reads and parses a
    CSV (tracemalloc): 1.6 million one-digit values (the densest a file can be) on NumPy's path, and on
    the cell-by-cell one (a comment line among the rows sends it there)."""
    import tracemalloc

    from hyde_bsdf.io.measurements import read_measurements

    out, head, rows = {}, "theta_i_deg,theta_r_deg,phi_deg,M01\n", "1,1,1,0\n" * 400_000
    for key, text in (("csv_bytes_per_value (NumPy's parser)", head + rows),
                      ("csv_bytes_per_value (cell by cell)", head + "# a comment\n" + rows)):
        path = tmp / "values.csv"
        path.write_text(text)
        tracemalloc.start()
        read_measurements(path)
        peak = tracemalloc.get_traced_memory()[1]
        tracemalloc.stop()
        out[key] = peak / (text.count(",") + text.count("\n") + 1)
    return out


LOADER = r"""
import os, sys
import mitsuba as mi
mi.set_variant("scalar_spectral_polarized")
def rss():
    return int(open("/proc/self/statm").read().split()[1]) * os.sysconf("SC_PAGE_SIZE")
before = rss()
bsdf = mi.load_dict({"type": "measured_polarized", "filename": sys.argv[1]})
print(rss() - before)
"""


def pbsdf(tmp):
    """Mitsuba loading a ~40 MB ``.pbsdf``: the rise of its resident size over the file size."""
    from hyde_bsdf.fit.pbsdf_export import export_pbsdf

    path = tmp / "table.pbsdf"
    export_pbsdf(path, rms_slope=0.3, n=1.5, resolution=(90, 45, 45), progress=False)
    rise = int(subprocess.run([sys.executable, "-c", LOADER, str(path)], cwd=ROOT, capture_output=True, text=True,
                              check=True).stdout.split()[-1])
    return {"pbsdf_loader_copies": rise / path.stat().st_size}


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--only", default="render,ad,forward,dense,fast,surface,stokes,pbrdf,csv,pbsdf")
    args = ap.parse_args(argv)
    from hyde_bsdf.resources import COSTS

    measured = {}
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        steps = {"render": lambda: {**render(tmp, "llvm_ad_spectral_polarized", True),
                                    **render(tmp, "llvm_ad_rgb", False)},
                 "ad": lambda: ad(tmp), "forward": lambda: forward(tmp), "dense": dense, "fast": fast,
                 "surface": surface, "stokes": stokes, "pbrdf": pbrdf, "csv": lambda: csv(tmp),
                 "pbsdf": lambda: pbsdf(tmp)}
        for name in args.only.split(","):
            t0 = time.perf_counter()
            measured.update(steps[name]())
            print(f"[bench_resources] {name}: {time.perf_counter() - t0:.0f} s", file=sys.stderr, flush=True)
    print(f"load average {os.getloadavg()[0]:.1f}, {os.cpu_count()} cores")
    print(f"{'entry':58s} {'measured':>11s} {'table':>11s} {'table/measured':>15s}")
    for key, value in measured.items():
        if isinstance(value, tuple):                     # a memory model at one size: (peak, estimate)
            value, entry = value
        else:
            entry = getattr(COSTS, key.split(" ")[0], None)
        ratio = f"{entry / value:15.2f}" if entry is not None and value > 0 else ""
        print(f"{key:58s} {value:11.4g} {'' if entry is None else f'{entry:11.4g}':>11s} {ratio}")
    print(json.dumps({k: float(v[0] if isinstance(v, tuple) else v) for k, v in measured.items()}))


if __name__ == "__main__":
    main()
