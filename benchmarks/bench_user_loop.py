"""The user's own optimisation loop, one BSDF per process: hyde against Mitsuba's roughconductor.

What users write (``mi.traverse``, ``mi.ad.Adam``, ``mi.render(scene, params, ...)``,
``dr.backward``), run for each BSDF in its **own fresh process** (as a user runs one BSDF), in both
orders (roughconductor first, then reversed), ``--blocks`` times; per BSDF the figure is the median
over blocks of the block's median iteration.  Per iteration, from Dr.Jit's kernel history
(``dr.JitFlag.KernelHistory``): the wall time, the kernels launched, their codegen + backend
(compile or cache lookup) time, their execution time, and the **host remainder** = wall - codegen -
execution (Python tracing, Mitsuba's C++ host work, synchronisation).  "kernels" counts the traced
(JIT) kernels, "launches" every launch (with memsets, copies, reductions).  Also the main thread's
CPU time per iteration (``time.thread_time``: tracing, codegen, host work, not the worker threads'
kernel execution), which a loaded machine inflates less than the wall time.

Loops (both: ``stokes`` around ``path`` max_depth 2, 8 spp, 4 scenes = 4 perspective views of
RES x RES px, each lit by its own directional light; one Adam variable written into all 4 scenes'
parameters, 4 renders per iteration each with its backward pass, then one Adam step):

``rough``  a 16 x 16 Beckmann alpha bitmap on a gold (``material="Au"``) rectangle.
``index``  8 x 8 eta and alpha bitmaps (k = 0) on a dielectric plane (the 2 bitmaps optimised).
           roughconductor's analogue: roughconductor with the same eta bitmap and k = 0 (the same
           reflection-only Fresnel model; roughdielectric would add transmission).

BSDFs: ``roughconductor`` (Beckmann, visible normals), ``hyde`` (default: V-groove shadowing,
paper diffuse term), ``hyde smith/none`` (shadowing smith, diffuse none: roughconductor's model).

Variants: ``llvm_ad_spectral_polarized`` unfrozen (spectral variants cannot use ``dr.freeze``) and
``llvm_ad_mono_polarized`` frozen (the renders + backward passes in one ``dr.freeze`` function).

    python benchmarks/bench_user_loop.py [--blocks 3] [--iterations 6] [--res 48] [--spp 8]
                                         [--loops rough,index] [--modes spectral,frozen] [--quick]

``--quick`` (< 1 minute on a quiet machine): the ``rough`` loop only, 16 px, 2 spp, 1 block, 2 iterations
after 1 warm-up one (4 frozen).
``--calls``: only the host (main-thread CPU) cost of tracing one eval / eval_pdf / sample / pdf of
each BSDF, the quantity the plugin's Python code adds to every render.
"""
from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys

import numpy as np

CONFIGS = {
    "roughconductor": None,
    "hyde": {},
    "hyde smith/none": {"shadowing": "smith", "diffuse": "none"},
}
MODES = {"spectral": ("llvm_ad_spectral_polarized", False), "frozen": ("llvm_ad_mono_polarized", True)}
#: (azimuth deg, elevation deg) of the 4 cameras; light j comes from azimuth + 150 deg, elevation 50
VIEWS = [(0.0, 55.0), (90.0, 50.0), (180.0, 60.0), (270.0, 45.0)]


def _orbit(az, el, r):
    a, e = np.radians(az), np.radians(el)
    return [float(r * np.cos(e) * np.cos(a)), float(r * np.cos(e) * np.sin(a)), float(r * np.sin(e))]


def maps(loop):
    """{traverse-key suffix: (truth, start)} float32 (rows, cols) maps of the loop's bitmaps."""
    n = 16 if loop == "rough" else 8
    y, x = np.mgrid[0:n, 0:n] / (n - 1.0)
    out = {"alpha": ((0.1 + 0.4 * x * (0.5 + 0.5 * y)).astype(np.float32), np.full((n, n), 0.3, np.float32))}
    if loop == "index":
        out["eta"] = ((1.3 + 0.4 * y).astype(np.float32), np.full((n, n), 1.5, np.float32))
    return out


def _bitmap(values):
    import mitsuba as mi

    return {"type": "bitmap", "bitmap": mi.Bitmap(np.asarray(values, np.float32)[..., None]), "raw": True}


def bsdf_dict(config, loop, values):
    """The loop's BSDF with the given maps ({name: array})."""
    if loop == "rough":
        index = {"material": "Au"}
    else:
        index = {"eta": _bitmap(values["eta"]), "k": 0.0}
    if config == "roughconductor":
        return {"type": "roughconductor", "distribution": "beckmann", "alpha": _bitmap(values["alpha"]), **index}
    return {"type": "hyde", "alpha": _bitmap(values["alpha"]), **index, **CONFIGS[config]}


def scene_dicts(config, loop, values, res, spp):
    """4 scenes: a 2 x 2 plane seen by view j and lit by directional light j."""
    import mitsuba as mi

    fmt = {"pixel_format": "luminance"} if mi.is_monochromatic else {}
    out = []
    for az, el in VIEWS:
        cam = {"type": "perspective", "fov": 40,
               "to_world": mi.ScalarTransform4f().look_at(origin=_orbit(az, el, 4.0), target=[0, 0, 0], up=[0, 0, 1]),
               "film": {"type": "hdrfilm", "width": res, "height": res, "rfilter": {"type": "box"}, **fmt},
               "sampler": {"type": "independent", "sample_count": spp}}
        light_dir = [-c for c in _orbit(az + 150.0, 50.0, 1.0)]
        out.append({"type": "scene",
                    "integrator": {"type": "stokes", "integrator": {"type": "path", "max_depth": 2}},
                    "sensor": cam,
                    "light": {"type": "directional", "direction": light_dir, "irradiance": 3.0},
                    "plane": {"type": "rectangle", "bsdf": bsdf_dict(config, loop, values)}})
    return out


def _setup(config, loop, res, spp):
    """The scenes (at the start maps), their parameters and keys, the references (rendered at the
    truth maps, 4x the samples), and the Adam optimiser holding the start maps."""
    import drjit as dr
    import mitsuba as mi

    m = maps(loop)
    scenes = [mi.load_dict(d) for d in scene_dicts(config, loop, {n: s for n, (t, s) in m.items()}, res, spp)]
    params = [mi.traverse(s) for s in scenes]
    keys = [{n: next(k for k in p.keys() if k.endswith(f"{n}.data")) for n in m} for p in params]
    refs = []
    for j, (s, p) in enumerate(zip(scenes, params)):
        for n, (truth, _) in m.items():
            p[keys[j][n]] = mi.TensorXf(truth[..., None])
        p.update()
        refs.append(dr.detach(mi.render(s, spp=4 * spp, seed=1000 + j)))
    dr.eval(refs)
    opt = mi.ad.Adam(lr=0.02)
    for n, (_, start) in m.items():
        opt[n] = mi.TensorXf(start[..., None])
    return scenes, params, keys, refs, opt


def write(params, keys, values):
    """Set the optimised maps into every scene (``params.update()``: the BSDFs' parameters_changed)."""
    for j, p in enumerate(params):
        for n, v in values.items():
            p[keys[j][n]] = v
        p.update()


def _step_function(params, spp):
    """One iteration's renders and backward passes: step(scenes, refs, values, seed) -> summed loss.
    ``values`` (the optimised maps, already written into the scenes) are inputs so that a
    ``dr.freeze`` recording sees them, as the references."""
    import drjit as dr
    import mitsuba as mi

    def step(scenes, refs, values, seed):
        total = dr.zeros(mi.Float, 1)
        for j, (scene, p) in enumerate(zip(scenes, params)):
            img = mi.render(scene, p, spp=spp, seed=seed + j)
            loss = dr.mean(dr.square(img - refs[j]), axis=None)
            dr.backward(loss)
            total = total + dr.detach(loss)
        return total

    return step


def run_child(config, loop, mode, iterations, warmup, res, spp):
    """Time ``iterations`` iterations (after ``warmup`` untimed ones) in this process: a dict of lists."""
    import gc
    import time

    import drjit as dr
    import mitsuba as mi

    variant, freeze = MODES[mode]
    mi.set_variant(variant)
    import hyde_bsdf

    hyde_bsdf.register(variant)
    scenes, params, keys, refs, opt = _setup(config, loop, res, spp)
    step = _step_function(params, spp)
    run = dr.freeze(step) if freeze else step
    warmup = max(warmup + 2, 4) if freeze else warmup     # a frozen function records up to 3 times in its first 4 calls
    dr.set_flag(dr.JitFlag.KernelHistory, True)
    rows = {"wall_ms": [], "cpu_ms": [], "kernels": [], "launches": [], "codegen_ms": [], "exec_ms": []}
    for it in range(warmup + iterations):
        if freeze:
            gc.collect()        # no NumPy-backed arrays freed through host callbacks during a recording
        dr.sync_thread()
        dr.kernel_history()     # clears the history
        t0, c0 = time.perf_counter(), time.thread_time()
        values = {n: opt[n] for n in opt.keys()}
        write(params, keys, values)
        loss = run(scenes, refs, values, dr.opaque(mi.UInt32, 7 * it))
        opt.step()
        for n in list(opt.keys()):
            opt[n] = dr.clip(opt[n], 0.01, 3.0)
        dr.eval(loss)
        dr.sync_thread()
        wall, cpu = 1e3 * (time.perf_counter() - t0), 1e3 * (time.thread_time() - c0)
        hist = dr.kernel_history()
        if it >= warmup:
            rows["wall_ms"].append(wall)
            rows["cpu_ms"].append(cpu)
            rows["kernels"].append(sum(str(h["type"]).endswith("JIT") for h in hist))   # traced kernels
            rows["launches"].append(len(hist))      # + memset/memcpy/reductions
            rows["codegen_ms"].append(sum(h.get("codegen_time", 0.0) + h.get("backend_time", 0.0) for h in hist))
            rows["exec_ms"].append(sum(h.get("execution_time", 0.0) for h in hist))
    return rows


def call_costs(variant="llvm_ad_spectral_polarized", lanes=1000, reps=40):
    """Main-thread CPU ms to trace one call of eval / eval_pdf / sample / pdf (no kernel launched) of
    each BSDF of the ``rough`` loop: the host cost a render pays per traced call (a render of this
    loop traces 9 eval_pdf + 6 sample per live instance, primal and backward pass)."""
    import time

    import drjit as dr
    import mitsuba as mi

    mi.set_variant(variant)
    import hyde_bsdf

    hyde_bsdf.register(variant)
    si = dr.zeros(mi.SurfaceInteraction3f, lanes)
    si.wi = dr.normalize(mi.Vector3f(0.1, 0.2, 1.0) + dr.zeros(mi.Vector3f, lanes))
    si.uv = mi.Point2f(0.3, 0.4)
    if mi.is_spectral:
        si.wavelengths = mi.UnpolarizedSpectrum(500.0, 550.0, 600.0, 650.0)
    wo = dr.normalize(mi.Vector3f(-0.1, 0.3, 1.0) + dr.zeros(mi.Vector3f, lanes))
    ctx, s1, s2 = mi.BSDFContext(), dr.full(mi.Float, 0.3, lanes), mi.Point2f(0.2, 0.7)
    out = {}
    for name in CONFIGS:
        bsdf = mi.load_dict(bsdf_dict(name, "rough", {"alpha": maps("rough")["alpha"][1]}))
        calls = {"eval": lambda: bsdf.eval(ctx, si, wo), "eval_pdf": lambda: bsdf.eval_pdf(ctx, si, wo),
                 "sample": lambda: bsdf.sample(ctx, si, s1, s2), "pdf": lambda: bsdf.pdf(ctx, si, wo)}
        out[name] = {}
        for call, fn in calls.items():
            fn()
            times = []
            for _ in range(5):
                t0 = time.thread_time()
                for _ in range(reps):
                    fn()
                times.append(1e3 * (time.thread_time() - t0) / reps)
            out[name][call] = float(np.median(times))
    print(f"\nhost cost of one traced call (main-thread CPU ms, {variant}, median of 5 x {reps}):")
    print(f"{'bsdf':16s}" + "".join(f" {c:>14s}" for c in out["roughconductor"]))
    for name, row in out.items():
        print(f"{name:16s}" + "".join(f" {v:7.3f} ({v / out['roughconductor'][c]:4.2f})" for c, v in row.items()))
    return out


FIELDS = ("wall_ms", "cpu_ms", "kernels", "launches", "codegen_ms", "exec_ms", "host_ms")


def _child(config, loop, mode, args):
    """Run one BSDF's loop in a fresh Python process; its per-iteration rows."""
    cmd = [sys.executable, os.path.abspath(__file__), "--child", json.dumps([config, loop, mode]),
           "--iterations", str(args.iterations), "--warmup", str(args.warmup), "--res", str(args.res),
           "--spp", str(args.spp)]
    out = subprocess.run(cmd, capture_output=True, text=True, env=dict(os.environ))
    if out.returncode != 0:
        raise RuntimeError(f"{config} / {loop} / {mode} failed:\n{out.stderr[-3000:]}")
    # Mitsuba's log may also go to stdout: the result is the last line
    rows = json.loads(out.stdout.strip().splitlines()[-1])
    rows["host_ms"] = [w - c - e for w, c, e in zip(rows["wall_ms"], rows["codegen_ms"], rows["exec_ms"])]
    return rows


def measure(loop, mode, args):
    """{config: {field: median over blocks of the block medians}}, blocks alternating the order."""
    names = list(CONFIGS)
    per_block = {n: [] for n in names}
    for b in range(args.blocks):
        for name in (names if b % 2 == 0 else names[::-1]):
            rows = _child(name, loop, mode, args)
            per_block[name].append({f: float(np.median(rows[f])) for f in FIELDS})
            print(f"[bench] {loop}/{mode} block {b + 1}/{args.blocks} {name}: "
                  f"{per_block[name][-1]['wall_ms']:.0f} ms/it, load {os.getloadavg()[0]:.2f}",
                  file=sys.stderr, flush=True)
    return {n: {f: float(np.median([blk[f] for blk in per_block[n]])) for f in FIELDS}
            | {"wall_blocks": [blk["wall_ms"] for blk in per_block[n]]} for n in names}


def report(loop, mode, result, renders=len(VIEWS)):
    """Print one table: per iteration, ratios to roughconductor, host remainder per render."""
    base = result["roughconductor"]
    variant, freeze = MODES[mode]
    print(f"\nloop {loop!r}, {variant}, {'frozen (dr.freeze)' if freeze else 'unfrozen'}: per iteration "
          f"({renders} renders + backward), median of block medians")
    print(f"{'bsdf':16s} {'wall ms':>8s} {'ratio':>6s} {'kernels':>8s} {'launches':>9s} {'codegen ms':>11s} "
          f"{'exec ms':>8s} {'host ms':>8s} {'host/render - rc':>17s} {'main CPU ms':>12s} {'ratio':>6s}  wall per block")
    for name, r in result.items():
        extra = (r["host_ms"] - base["host_ms"]) / renders
        blocks = " ".join(f"{w:.0f}" for w in r["wall_blocks"])
        print(f"{name:16s} {r['wall_ms']:8.1f} {r['wall_ms'] / base['wall_ms']:6.3f} {r['kernels']:8.0f} "
              f"{r['launches']:9.0f} {r['codegen_ms']:11.1f} {r['exec_ms']:8.1f} {r['host_ms']:8.1f} "
              f"{extra:+17.1f} {r['cpu_ms']:12.1f} {r['cpu_ms'] / base['cpu_ms']:6.3f}  {blocks}")


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--blocks", type=int, default=3, help="fresh processes per BSDF (orders alternate)")
    ap.add_argument("--iterations", type=int, default=6, help="timed iterations per process")
    ap.add_argument("--warmup", type=int, default=2,
                    help="untimed iterations first (JIT compilation; frozen: 2 more, at least 4: it records up to 3 times)")
    ap.add_argument("--res", type=int, default=48)
    ap.add_argument("--spp", type=int, default=8)
    ap.add_argument("--loops", default="rough,index")
    ap.add_argument("--modes", default="spectral,frozen")
    ap.add_argument("--quick", action="store_true", help="rough loop, 16 px, 2 spp, 1 block, 2 iterations")
    ap.add_argument("--calls", action="store_true", help="only the host cost of one traced eval/eval_pdf/sample/pdf")
    ap.add_argument("--child", default=None, help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.child:
        config, loop, mode = json.loads(args.child)
        print(json.dumps(run_child(config, loop, mode, args.iterations, args.warmup, args.res, args.spp)))
        return 0
    if args.calls:
        call_costs()
        return 0
    if args.quick:
        args.loops, args.res, args.spp, args.blocks, args.iterations, args.warmup = "rough", 16, 2, 1, 2, 1
    loops, modes = args.loops.split(","), args.modes.split(",")
    bad = [x for x in loops if x not in ("rough", "index")] + [x for x in modes if x not in MODES]
    if bad or min(args.blocks, args.iterations, args.res, args.spp) < 1 or args.warmup < 1:
        ap.error(f"loops: rough,index; modes: {','.join(MODES)}; blocks, iterations, warmup, res, spp >= 1"
                 + (f" (got {', '.join(bad)})" if bad else ""))
    load0 = os.getloadavg()
    results = {(loop, mode): measure(loop, mode, args) for loop in loops for mode in modes}
    print(f"bench_user_loop: {args.res}x{args.res} px per view, {args.spp} spp, {args.blocks} blocks x "
          f"{args.iterations} iterations (after {args.warmup} warm-up), {os.cpu_count()} CPU threads; "
          f"load average (1 min) {load0[0]:.2f} at start, {os.getloadavg()[0]:.2f} at end")
    for (loop, mode), result in results.items():
        report(loop, mode, result)
    return 0


if __name__ == "__main__":
    sys.exit(main())
