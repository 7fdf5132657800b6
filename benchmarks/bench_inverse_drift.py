"""hyde and roughconductor **interleaved in one process**: does the loop drift as it runs?

What it measures.  The loop a user writes for roughconductor (``mi.traverse`` + ``mi.ad.Adam`` on a
16 x 16 alpha bitmap, one plane seen by 3 views of RES x RES px, SPP samples per pixel, unfrozen, one
``mi.render`` + ``dr.backward`` per iteration), run for both BSDFs in ONE process with their
iterations interleaved; prints the median iteration time per block of ten iterations and the ratio
hyde / roughconductor per block.  A per-process drift (a cache, a registry or an AD graph that
grows) would show as times rising from block to block; none was measured (2026-12-02: flat blocks).

What it does NOT measure: the plugin's cost against roughconductor's in a user's loop.  With both
scenes alive, every render traces the BSDFs of BOTH scenes: the integrator's BSDF dispatch is a
symbolic Dr.Jit virtual function call, which records every live instance of the ``BSDF`` domain
(Dr.Jit cannot know which pointers the call will see), so a roughconductor render also traces the
hyde plugin's Python ``eval_pdf``/``sample`` (measured: 2 of each per live hyde instance per
primal render; a roughconductor render's main-thread CPU time went from 11 to 34 ms with 4 hyde
scenes alive, back to 14 ms once they were deleted).  The two BSDFs' iterations then cost nearly
the same and the ratio reads ~1.0 whatever the plugin costs (this script reported 1.03-1.06 where
one BSDF per process gave 1.46-1.64).  Mitsuba's developers describe the same effect for sensors:
mitsuba-renderer/mitsuba3 issue 1700 ("Dr.Jit is unaware of that and cautiously records/traces all
200 of them"; their advice: keep alive only what a render needs, or ``dr.freeze``).  Use
``bench_user_loop.py`` (one BSDF per fresh process) for the ratio.

    python benchmarks/bench_inverse_drift.py [--iterations 40] [--res 48] [--spp 8]
                                             [--variant llvm_ad_spectral_polarized]
"""
from __future__ import annotations

import argparse
import sys
import time

import numpy as np


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--iterations", type=int, default=40)
    ap.add_argument("--res", type=int, default=48)
    ap.add_argument("--spp", type=int, default=8)
    ap.add_argument("--variant", default="llvm_ad_spectral_polarized")
    args = ap.parse_args(argv)
    if args.iterations < 20 or args.res < 8 or args.spp < 1:
        ap.error("need --iterations >= 20, --res >= 8, --spp >= 1")

    import drjit as dr
    import mitsuba as mi

    from hyde_bsdf import inverse as inv

    inv.prepare(args.variant)
    truth = inv.observations.example_maps(16)
    setups = {}
    for name in ("hyde", "roughconductor"):
        scene = mi.load_dict(inv.observations.plane_scene_dict(truth, bsdf=name, light=0, res=args.res, spp=args.spp))
        ref = mi.render(scene, spp=4 * args.spp, seed=0)
        params = mi.traverse(scene)
        key = next(k for k in params.keys() if k.endswith("alpha.data"))
        opt = mi.ad.Adam(lr=0.05)
        opt[key] = mi.TensorXf(np.full(truth.shape + (1,), 0.3, np.float32))
        params.update(opt)
        setups[name] = (scene, params, opt, key, ref)
    times = {n: [] for n in setups}
    for it in range(args.iterations):
        for name, (scene, params, opt, key, ref) in setups.items():
            t = time.perf_counter()
            img = mi.render(scene, params, spp=args.spp, seed=it + 1)
            loss = dr.mean(dr.square(img - ref), axis=None)
            dr.backward(loss)
            opt.step()
            opt[key] = dr.clip(opt[key], 0.01, 1.0)
            params.update(opt)
            dr.eval(loss)
            dr.sync_thread()
            times[name].append(time.perf_counter() - t)
        print(f"\r[drift] iteration {it + 1}/{args.iterations}", end="", file=sys.stderr, flush=True)
    print(file=sys.stderr)
    blocks = [(a, min(a + 10, args.iterations)) for a in range(1, args.iterations, 10)]   # skip the compiling one
    h, r = np.array(times["hyde"]), np.array(times["roughconductor"])
    print(f"plain unfrozen loop, {args.variant}, 3 views of {args.res}x{args.res} px, {args.spp} spp, "
          f"16x16 alpha bitmap: median iteration time per block")
    print(f"{'iterations':>12s} {'hyde s':>8s} {'roughconductor s':>17s} {'ratio':>6s}")
    for a, b in blocks:
        mh, mr = float(np.median(h[a:b])), float(np.median(r[a:b]))
        print(f"{a + 1:>5d}-{b:<6d} {mh:8.3f} {mr:17.3f} {mh / mr:6.3f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
