"""Where a render's host time goes per ``hyde`` instance (issue 31, cost per instance).

One scene of ``bench_render.py --instances`` (M spheres with M distinct materials, 96 x 72, 1 spp,
``llvm_ad_rgb``) in this process; after warm-up renders, the main thread's CPU time per render
(Python tracing of every instance's BSDF methods inside Mitsuba's symbolic calls, and Dr.Jit's
assembly of one callable per instance) and, for hyde, the part spent inside each of the plugin's
methods and helpers (thread-time counters wrapped around them; nested calls are counted in each
enclosing one), and the number of Dr.Jit variables one render creates (the operations traced, by Python
or C++).  A Python BSDF that does almost nothing (``--bsdf trivial``) shows the cost of a
Python instance as such; ``--bsdf pyrough`` is roughconductor's own model written in Python with Mitsuba's
C++ building blocks (``bench_render.python_floor_class``): the floor of a Python plugin of that model.

    python benchmarks/bench_render_trace.py [--bsdf "hyde default"] [--materials 50] [--renders 5]
"""
from __future__ import annotations

import argparse
import collections
import sys
import time
from pathlib import Path

import drjit as dr
import mitsuba as mi

sys.path.insert(0, str(Path(__file__).resolve().parent))
import bench_render  # noqa: E402

VARIANT = bench_render.INSTANCE_VARIANT
#: the plugin's methods and helpers that are timed (those the integrator reaches per instance)
METHODS = ("sample", "eval_pdf", "_eval_pdf", "_sample_specular", "_lobe", "_value", "_pdf", "_mueller", "_diffuse",
           "_geometry", "_rough", "_index", "_scale", "_p_spec", "_distr")


def _trivial_class():
    class Trivial(mi.BSDF):
        """A cosine lobe of albedo 0.5: the least a Python BSDF traces."""

        def __init__(self, props):
            mi.BSDF.__init__(self, props)
            self.m_flags = mi.BSDFFlags.DiffuseReflection | mi.BSDFFlags.FrontSide
            self.m_components = [self.m_flags]
            self.m_value = props.get("value", 0.5)

        def sample(self, ctx, si, sample1, sample2, active=True):
            bs = dr.zeros(mi.BSDFSample3f)
            bs.wo = mi.warp.square_to_cosine_hemisphere(sample2)
            bs.pdf = mi.warp.square_to_cosine_hemisphere_pdf(bs.wo)
            bs.eta, bs.sampled_type, bs.sampled_component = 1.0, mi.UInt32(+self.m_flags), mi.UInt32(0)
            return bs, mi.Spectrum(self.m_value)

        def eval(self, ctx, si, wo, active=True):
            return mi.Spectrum(self.m_value) * dr.maximum(mi.Frame3f.cos_theta(wo), 0.0) * dr.inv_pi

        def pdf(self, ctx, si, wo, active=True):
            return mi.warp.square_to_cosine_hemisphere_pdf(wo)

        def eval_pdf(self, ctx, si, wo, active=True):
            return self.eval(ctx, si, wo, active), self.pdf(ctx, si, wo, active)

        def traverse(self, callback):
            pass

        def to_string(self):
            return "Trivial[]"
    return Trivial


def _timers(cls, counters):
    def wrap(name, fn):
        def timed(*args, **kwargs):
            t0 = time.thread_time()
            try:
                return fn(*args, **kwargs)
            finally:
                counters[name][0] += time.thread_time() - t0
                counters[name][1] += 1
        return timed
    for name in METHODS:
        if name in cls.__dict__ and not isinstance(cls.__dict__[name], staticmethod):
            setattr(cls, name, wrap(name, cls.__dict__[name]))


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--bsdf", default="hyde default",
                   help="roughconductor, 'hyde smith/none', 'hyde default', trivial or pyrough")
    p.add_argument("--materials", type=int, default=50)
    p.add_argument("--renders", type=int, default=5)
    args = p.parse_args(argv)
    bench_render.prepare_variant(VARIANT, fallback=False)
    counters = collections.defaultdict(lambda: [0.0, 0])
    config = "roughconductor" if args.bsdf in ("trivial", "pyrough") else args.bsdf
    d = bench_render.instance_scene(config, args.materials, 96, 72)
    if args.bsdf == "trivial":
        mi.register_bsdf("trivial_python", lambda props, cls=_trivial_class(): cls(props))
        for i in range(args.materials):
            d[f"sphere{i}"]["bsdf"] = {"type": "trivial_python", "value": 0.3 + 0.01 * i}
    elif args.bsdf == "pyrough":
        bench_render.register_python_floor()
        d = bench_render.instance_scene(bench_render.FLOOR, args.materials, 96, 72)
    elif args.bsdf.startswith("hyde"):
        from hyde_bsdf.mitsuba.plugin import plugin_class
        _timers(plugin_class(), counters)
    scene = mi.load_dict(d)
    for seed in range(3):
        dr.eval(mi.render(scene, spp=1, seed=seed))
    dr.sync_thread()
    counters.clear()
    times = []
    for seed in range(args.renders):
        t0 = time.thread_time()
        dr.eval(mi.render(scene, spp=1, seed=10 + seed))
        dr.sync_thread()
        times.append(1e3 * (time.thread_time() - t0))
    main_ms = sorted(times)[len(times) // 2]
    per_call = {name: tuple(c) for name, c in counters.items()}
    # Dr.Jit variables one render creates (traced operations, the integrator's included): with index reuse
    # off, every new variable takes the next index
    dr.set_flag(dr.JitFlag.ReuseIndices, False)
    first = dr.opaque(mi.Float, 0.0).index & 0xFFFFFFFF
    dr.eval(mi.render(scene, spp=1, seed=99))
    created = (dr.opaque(mi.Float, 0.0).index & 0xFFFFFFFF) - first - 1
    dr.set_flag(dr.JitFlag.ReuseIndices, True)
    print(f"{args.bsdf}, {args.materials} materials, {VARIANT}: main thread {main_ms:.1f} ms per render "
          f"(median of {args.renders}), {main_ms / args.materials:.2f} ms per material; {created} Dr.Jit "
          f"variables created per render ({created / args.materials:.0f} per material)")
    for name, (seconds, calls) in sorted(per_call.items(), key=lambda kv: -kv[1][0]):
        print(f"  in {name:18s} {1e3 * seconds / args.renders:8.2f} ms per render, {calls / args.renders:5.0f} calls, "
              f"{1e6 * seconds / max(calls, 1):6.1f} us per call")
    return 0


if __name__ == "__main__":
    sys.exit(main())
