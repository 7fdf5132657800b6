"""Time per inverse-rendering iteration and peak memory: hyde against Mitsuba's roughconductor.

One iteration = set the parameters, ``mi.render(scene, params, spp, seed)`` through
``stokes`` around ``path`` (llvm_ad_spectral_polarized), the masked Stokes loss,
``dr.backward``, one ``mi.ad.Adam`` step (exactly hyde_bsdf.render.inverse.invert).  Each
material runs in its own fresh process (so the peak resident memory is its own):
the scene of scenes/inverse.xml at ``--res`` x ``--res`` pixels and ``--spp`` samples,
``--iterations`` iterations; reported: the first iteration (includes the JIT
compilation), the median of the later ones, and the process's resident memory
before the loop and at its peak (ru_maxrss).  roughconductor gets the same
Beckmann roughness (alpha = sqrt(2) rms_slope) and the same eta, k; it has no
diffuse term and uses Smith shadowing, so it is the cost floor of a conductor lobe.
The multijitter sampler rounds sample counts to a product of two near-equal integers
(16 stays 16; 32 becomes 35): prefer squares.

    python benchmarks/bench_inverse.py [--res 64] [--spp 16] [--iterations 40] [--csv out/bench_inverse.csv]
"""
from __future__ import annotations

import argparse
import json
import os
import resource
import subprocess
import sys

CONFIGS = {
    "hyde": {"bsdf": "hyde", "diffuse": "paper"},
    "hyde (diffuse none)": {"bsdf": "hyde", "diffuse": "none"},
    "roughconductor": {"bsdf": "roughconductor", "diffuse": "paper"},
}


def _rss_mib():
    with open("/proc/self/status") as fh:
        for line in fh:
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) / 1024.0
    return float("nan")


def run_one(name, res, spp, iterations):
    import numpy as np

    from hyde_bsdf.render import inverse as inv

    cfg = CONFIGS[name]
    inv.prepare()
    scene = inv.load_scene(None, res=res, spp=spp, bsdf=cfg["bsdf"], diffuse=cfg["diffuse"])
    ref = inv.render_reference(scene, inv.TRUTH, 4 * spp, seed=0, bsdf=cfg["bsdf"])
    loss = inv.StokesLoss(ref)
    rss0 = _rss_mib()
    r = inv.invert(scene, loss, inv.START, iterations=iterations, spp=spp, seed=1, bsdf=cfg["bsdf"],
                   progress=False)
    t = np.array([h["seconds"] for h in r.history])
    per = np.diff(t)
    return {"config": name, "res": res, "spp": spp, "iterations": iterations,
            "first_iteration_s": r.first_iteration_seconds,
            "median_iteration_s": float(np.median(per[2:] if per.size > 4 else per)),
            "rss_before_loop_mib": rss0,
            "peak_rss_mib": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0,
            "final_loss": r.history[-1]["loss"]}


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--res", type=int, default=64)
    ap.add_argument("--spp", type=int, default=16)
    ap.add_argument("--iterations", type=int, default=40)
    ap.add_argument("--csv", default=None, help="also write the table here")
    ap.add_argument("--one", default=None, help=argparse.SUPPRESS)   # child process: one config
    args = ap.parse_args(argv)
    if args.one:
        print(json.dumps(run_one(args.one, args.res, args.spp, args.iterations)))
        return 0
    rows = []
    for name in CONFIGS:
        print(f"[bench] {name} ...", file=sys.stderr, flush=True)
        out = subprocess.run([sys.executable, __file__, "--one", name, "--res", str(args.res), "--spp",
                              str(args.spp), "--iterations", str(args.iterations)],
                             capture_output=True, text=True, env=dict(os.environ))
        if out.returncode != 0:
            print(out.stderr, file=sys.stderr)
            return 1
        # Mitsuba's log (e.g. the multijitter sampler's rounding warning) also goes to stdout
        rows.append(json.loads(out.stdout[out.stdout.rindex('{"config"'):].splitlines()[0]))
    base = next(r for r in rows if r["config"] == "roughconductor")
    print(f"inverse-rendering iteration, llvm_ad_spectral_polarized, {args.res}x{args.res}, {args.spp} spp, "
          f"{args.iterations} iterations, {os.cpu_count()} CPU threads")
    print(f"{'config':22s} {'first it (JIT) s':>17s} {'median it s':>12s} {'ratio':>6s} "
          f"{'RSS before MiB':>15s} {'peak RSS MiB':>13s}")
    for r in rows:
        r["ratio_to_roughconductor"] = r["median_iteration_s"] / base["median_iteration_s"]
        print(f"{r['config']:22s} {r['first_iteration_s']:17.2f} {r['median_iteration_s']:12.3f} "
              f"{r['ratio_to_roughconductor']:6.2f} {r['rss_before_loop_mib']:15.0f} {r['peak_rss_mib']:13.0f}")
    if args.csv:
        import csv

        os.makedirs(os.path.dirname(os.path.abspath(args.csv)), exist_ok=True)
        with open(args.csv, "w", newline="") as fh:
            w = csv.DictWriter(fh, fieldnames=list(rows[0]))
            w.writeheader()
            w.writerows(rows)
    return 0


if __name__ == "__main__":
    sys.exit(main())
