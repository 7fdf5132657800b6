"""The Stokes step on camera-sized frames: time and peak memory of ``stokes_from_mosaic`` on a DoFP raw
mosaic (default 2448 x 2048, 5 MP, the common Sony polarization sensor), super-pixel against
bilinear demosaicking, each in its own fresh process (so the peak resident memory, ru_maxrss, is its
own).  Reported: median seconds over ``--rounds``, seconds per megapixel, the bilinear / super-pixel
ratio, and the peak resident memory above the process's baseline (NumPy imported, mosaic loaded).

    python benchmarks/bench_stokes.py [--width 2448] [--height 2048] [--rounds 3]

Measured 2026-12-02 on the shared 2-core machine (load ~7), 2448 x 2048 uint16 mosaic, one round
each (``--rounds 1``): super-pixel 1.24 s (0.25 s/MP; 1224 x 1024 Stokes pixels), bilinear 23.6 s
(2448 x 2048; 19x: the 13 separable 3 x 3 convolutions of the normalised interpolation, memory-bound),
peak process memory 293 and 855 MB.
"""
from __future__ import annotations

import argparse
import json
import resource
import subprocess
import sys
import time


def _one(method: str, width: int, height: int, rounds: int) -> dict:
    import numpy as np

    from hyde_bsdf.model.polarimetry import CameraNoise, simulate_mosaic, stokes_from_mosaic

    noise = CameraNoise(gain=1.0, read_noise=3.0, full_well=30000.0, black_level=64.0)
    S = np.zeros((4, height // 2, width // 2))
    S[0], S[1], S[2] = 5000.0, 1000.0, -500.0
    raw = np.round(simulate_mosaic(S, noise, np.random.default_rng(0))).astype(np.uint16)
    base = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    times = []
    for _ in range(rounds):
        t0 = time.perf_counter()
        stokes_from_mosaic(raw, noise=noise, method=method)
        times.append(time.perf_counter() - t0)
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    return {"seconds": sorted(times)[len(times) // 2], "extra_mb": (peak - base) / 1024, "peak_mb": peak / 1024}


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--width", type=int, default=2448)
    ap.add_argument("--height", type=int, default=2048)
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--child", default=None, help=argparse.SUPPRESS)
    a = ap.parse_args()
    if a.child:
        print(json.dumps(_one(a.child, a.width, a.height, a.rounds)))
        return 0
    out = {}
    for method in ("superpixel", "bilinear"):
        res = subprocess.run([sys.executable, __file__, "--child", method, "--width", str(a.width), "--height",
                              str(a.height), "--rounds", str(a.rounds)], capture_output=True, text=True, check=True)
        out[method] = json.loads(res.stdout.strip().splitlines()[-1])
        mp = a.width * a.height / 1e6
        r = out[method]
        print(f"{method:10s} {r['seconds']:.2f} s ({r['seconds'] / mp:.2f} s/MP), peak {r['peak_mb']:.0f} MB "
              f"(+{r['extra_mb']:.0f} MB over the loaded mosaic)")
    print(f"bilinear / superpixel time: {out['bilinear']['seconds'] / out['superpixel']['seconds']:.1f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
