"""Property test (Hypothesis) of the plugin's ``eval`` / ``pdf`` / ``sample`` at random and edge inputs.

Inputs include directions at, just above and below the horizon, normal and grazing incidence,
rms_slope (or alpha) at the ends of the accepted range and beyond it, k = 0 (dielectrics) up to
1e7 (beyond the accepted 1e6), eta = 0, every shadowing/diffuse switch, both transport modes and sample values at 0 and
just below 1.  The property: a parameter outside the accepted range is refused at load with a
``ValueError`` naming it; everything else gives finite values (never NaN or Inf), pdf >= 0, and
a sample weight that is finite and zero where the pdf is.

Directions within 1e-38 ... 1e-3 of the normal and of each other (issue 15: wi along the normal and
wo 1e-30 away gave NaN Mueller rows for every material) are covered in float32, by a Hypothesis
test in a scalar variant and a deterministic grid in the LLVM variant; near the normal the Mueller
matrix must also be continuous (equal to its value at exact normal incidence).  The profile is
chosen in ``conftest.py``: derandomized in CI, every failure found so far pinned as an ``@example``.
"""
import math

import numpy as np
import pytest
from conftest import examples
from hypothesis import HealthCheck, example, given, settings
from hypothesis import strategies as st

from hyde_bsdf.mitsuba.variants import set_variant

HALF_PI = 0.5 * math.pi
THETAS = st.one_of(st.sampled_from([0.0, 1e-7, 0.3, HALF_PI - 1e-4, HALF_PI - 1e-7, HALF_PI,
                                    HALF_PI + 1e-6, HALF_PI + 0.2, math.pi]),
                   st.floats(0.0, math.pi))
PHIS = st.floats(0.0, 2 * math.pi)
ROUGH = st.one_of(st.sampled_from([1e-4, 1e-4 * (1 + 1e-5), 50.0, 49.999, 0.3, 0.0, 1e-5, 51.0, 1e3]),
                  st.floats(math.log(1e-4), math.log(50.0)).map(math.exp))
KS = st.one_of(st.sampled_from([0.0, 1e-9, 1e-3, 7.35, 1e3, 1e7, -1.0]), st.floats(0.0, 1e7))
ETAS = st.one_of(st.sampled_from([0.0, 1e-6, 1.0, 1.5, 100.0]), st.floats(0.0, 100.0))
UNIT = st.one_of(st.sampled_from([0.0, 1.0 - 2.0 ** -24, 0.5]), st.floats(0.0, 1.0, exclude_max=True))


def _vec(theta, phi):
    s = math.sin(theta)
    return [s * math.cos(phi), s * math.sin(phi), math.cos(theta)]


def _finite(x):
    return bool(np.isfinite(np.asarray(x, dtype=float)).all())


def _check(mi, bsdf, wi, wo, s1, s2, mode):
    import drjit as dr

    ctx = mi.BSDFContext(mode)
    si = dr.zeros(mi.SurfaceInteraction3f)
    si.wi = mi.Vector3f(*wi)
    si.uv = mi.Point2f(0.3, 0.7)
    si.wavelengths = mi.UnpolarizedSpectrum(400.0, 500.0, 600.0, 700.0)
    wo = mi.Vector3f(*wo)
    value = bsdf.eval(ctx, si, wo)
    pdf = bsdf.pdf(ctx, si, wo)
    v2, p2 = bsdf.eval_pdf(ctx, si, wo)
    assert _finite(value) and _finite(pdf) and _finite(v2) and _finite(p2), (value, pdf)
    assert float(pdf) >= 0.0
    bs, weight = bsdf.sample(ctx, si, s1, mi.Point2f(*s2))
    assert _finite(weight) and math.isfinite(float(bs.pdf)), (weight, bs.pdf)
    assert float(bs.pdf) >= 0.0
    if float(bs.pdf) == 0.0:
        assert float(np.abs(np.asarray(weight, dtype=float)).max()) == 0.0


@settings(max_examples=examples(250), deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(rough=ROUGH, spelling=st.sampled_from(["rms_slope", "alpha"]), eta=ETAS, k=KS,
       shadowing=st.sampled_from(["vgroove", "smith", "none"]),
       diffuse=st.sampled_from(["paper", "reciprocal", "none"]), visible=st.booleans(),
       ti=THETAS, pi=PHIS, to=THETAS, po=PHIS, s1=UNIT, s2a=UNIT, s2b=UNIT,
       importance=st.booleans())
@example(rough=0.3, spelling="rms_slope", eta=0.0, k=1.0, shadowing="vgroove", diffuse="paper", visible=True,
         ti=0.0, pi=0.0, to=1e-30, po=0.0, s1=0.5, s2a=0.5, s2b=0.5, importance=False)   # issue 15: NaN rows
@example(rough=0.5, spelling="alpha", eta=0.2, k=3.0, shadowing="smith", diffuse="none", visible=False,
         ti=1e-20, pi=0.0, to=0.0, po=0.0, s1=0.5, s2a=0.5, s2b=0.5, importance=True)   # Mitsuba's smith_g1 NaN
@example(rough=1e-4, spelling="rms_slope", eta=1.5, k=0.0, shadowing="vgroove", diffuse="paper", visible=True,
         ti=HALF_PI - 1e-38, pi=0.0, to=HALF_PI - 1e-38, po=math.pi, s1=0.5, s2a=0.5, s2b=0.5,
         importance=False)                                                 # float32 overflow of D G / cos
def test_eval_pdf_sample_finite_or_refused(rough, spelling, eta, k, shadowing, diffuse, visible,
                                           ti, pi, to, po, s1, s2a, s2b, importance):
    import mitsuba as mi
    import hyde_bsdf

    set_variant("scalar_spectral_polarized", fallback=False)
    hyde_bsdf.register("scalar_spectral_polarized")
    from hyde_bsdf.mitsuba.plugin import plugin_class
    from hyde_bsdf.model.parameters import ALPHA, ETA, RMS_SLOPE
    from hyde_bsdf.model.terms import allowed

    INDEX_MAX = ETA.hi
    lo, hi = RMS_SLOPE if spelling == "rms_slope" else ALPHA
    props = mi.Properties("hyde")
    props[spelling] = rough
    props["eta"], props["k"] = eta, k
    props["shadowing"], props["diffuse"], props["sample_visible"] = shadowing, diffuse, visible
    # textures hold float32: an index that rounds to 0 is 0
    # below the lower bound (>= 0) is floored with a warning; eta, k in [0, INDEX_MAX]
    invalid = (not 0.0 <= rough <= hi * (1 + 1e-6)) or k < 0 or np.float32(k) > INDEX_MAX \
        or np.float32(eta) > INDEX_MAX \
        or (np.float32(eta) == 0 and np.float32(k) == 0) \
        or not allowed(shadowing, diffuse)
    if invalid:
        with pytest.raises(ValueError, match="hyde: "):
            plugin_class()(props)
        return
    bsdf = plugin_class()(props)
    mode = mi.TransportMode.Importance if importance else mi.TransportMode.Radiance
    _check(mi, bsdf, _vec(ti, pi), _vec(to, po), s1, (s2a, s2b), mode)


def test_llvm_batch_at_edges_is_finite():
    """The float32 LLVM path over a grid of edge directions, roughness ends and extreme k."""
    import drjit as dr
    import mitsuba as mi
    import hyde_bsdf

    set_variant("llvm_ad_spectral_polarized", fallback=False)
    hyde_bsdf.register("llvm_ad_spectral_polarized")
    thetas = np.array([0.0, 1e-7, 0.7, HALF_PI - 1e-4, HALF_PI - 1e-7, HALF_PI, HALF_PI + 1e-3, math.pi])
    phis = np.array([0.0, 1.0, math.pi, 4.0])
    t_i, p_i, t_o, p_o = (a.ravel() for a in np.meshgrid(thetas, phis, thetas, phis, indexing="ij"))
    n = t_i.size
    wi = mi.Vector3f(*(mi.Float(np.float32(c)) for c in np.array([_vec(a, b) for a, b in zip(t_i, p_i)]).T))
    wo = mi.Vector3f(*(mi.Float(np.float32(c)) for c in np.array([_vec(a, b) for a, b in zip(t_o, p_o)]).T))
    si = dr.zeros(mi.SurfaceInteraction3f, n)
    si.wi = wi
    si.wavelengths = mi.UnpolarizedSpectrum(450.0, 550.0, 650.0, 750.0)
    rng = np.random.default_rng(0)
    s1 = mi.Float(np.where(np.arange(n) % 3 == 0, 0.0, rng.uniform(0, 1, n)).astype(np.float32))
    s2 = mi.Point2f(mi.Float(rng.uniform(0, 1, n).astype(np.float32)),
                    mi.Float(np.where(np.arange(n) % 5 == 0, 1 - 2 ** -24, rng.uniform(0, 1, n)).astype(np.float32)))
    for rough in (1e-4, 50.0):
        for eta, k in ((1.5, 0.0), (0.0, 1e6), (0.285, 7.35)):
            for shadowing, diffuse in (("vgroove", "paper"), ("smith", "reciprocal"), ("none", "paper")):
                b = mi.load_dict({"type": "hyde", "rms_slope": rough, "eta": eta, "k": k,
                                  "shadowing": shadowing, "diffuse": diffuse})
                for mode in (mi.TransportMode.Radiance, mi.TransportMode.Importance):
                    ctx = mi.BSDFContext(mode)
                    v, p = b.eval_pdf(ctx, si, wo)
                    bs, w = b.sample(ctx, si, s1, s2)
                    for x in (v, p, w, bs.pdf):
                        assert _finite(x), (rough, eta, k, shadowing, diffuse, mode)
                    assert float(dr.min(p)[0]) >= 0 and float(dr.min(bs.pdf)[0]) >= 0


TINY = st.floats(-38.0, -3.0).map(lambda e: 10.0 ** e)


def _tilt(v, eps, phi):
    """The unit vector at angle ~eps from unit vector v, towards azimuth phi around it (float64)."""
    v = np.asarray(v, float)
    a = np.array([1.0, 0.0, 0.0]) if abs(v[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    t1 = np.cross(v, a)
    t1 /= np.linalg.norm(t1)
    t2 = np.cross(v, t1)
    w = v + eps * (math.cos(phi) * t1 + math.sin(phi) * t2)
    return list(w / np.linalg.norm(w))


#: pairs (wi, wo) of nearly collinear directions: along the normal, backscatter, mirror, grazing
def _near_pairs(eps, phi):
    z = [0.0, 0.0, 1.0]
    g = _vec(0.7, 0.4)
    mirror = _vec(0.7, 0.4 + math.pi)
    return {
        "wi normal, wo near it": (z, _tilt(z, eps, phi)),
        "wo normal, wi near it": (_tilt(z, eps, phi), z),
        "both near the normal": (_tilt(z, eps, phi), _tilt(z, eps, phi + 2.0)),
        "backscatter, wo = wi + eps": (g, _tilt(g, eps, phi)),
        "mirror direction + eps": (g, _tilt(mirror, eps, phi)),
        "wi = -wo at grazing + eps": ([1.0, 0.0, eps], [-1.0, eps * math.sin(phi), eps]),
    }


@settings(max_examples=examples(60), deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(eps=TINY, phi=PHIS, case=st.sampled_from(sorted(_near_pairs(1e-3, 0.0))),
       material=st.sampled_from(["Au", "glass", "mirror"]), rough=st.sampled_from([1e-4, 0.3, 50.0]),
       shadowing=st.sampled_from(["vgroove", "smith", "none"]), importance=st.booleans())
@example(eps=1e-30, phi=0.0, case="wi normal, wo near it", material="Au", rough=0.3, shadowing="vgroove",
         importance=False)                                                 # issue 15
def test_near_collinear_directions_are_finite_float32(eps, phi, case, material, rough, shadowing, importance):
    import mitsuba as mi
    import hyde_bsdf

    set_variant("scalar_spectral_polarized", fallback=False)
    hyde_bsdf.register("scalar_spectral_polarized")
    index = {"Au": {"material": "Au"}, "glass": {"eta": 1.5, "k": 0.0}, "mirror": {}}[material]
    bsdf = mi.load_dict({"type": "hyde", "rms_slope": rough, "shadowing": shadowing, **index})
    wi, wo = _near_pairs(eps, phi)[case]
    mode = mi.TransportMode.Importance if importance else mi.TransportMode.Radiance
    _check(mi, bsdf, wi, wo, 0.3, (0.4, 0.6), mode)


def test_near_collinear_grid_llvm_is_finite_and_continuous_at_the_normal():
    """Every offset 1e-38 ... 1e-3 (each decade) of every near-collinear case, float32 LLVM, every
    shadowing/diffuse switch and both transport modes, at rms_slope 1e-4, 0.3 and 50 for a metal
    (0.2 + 3i) and a dielectric (1.5), given per lane by 2 x 3 nearest-neighbour bitmaps (one
    kernel per switch): finite eval/pdf/sample, pdf >= 0.  Near the normal (eps <= 1e-6) the
    Mueller matrix equals its value at exact normal incidence (relative 1e-5)."""
    import drjit as dr
    import mitsuba as mi
    import hyde_bsdf

    set_variant("llvm_ad_spectral_polarized", fallback=False)
    hyde_bsdf.register("llvm_ad_spectral_polarized")
    roughs, etas, ks = [1e-4, 0.3, 50.0], [0.2, 1.5], [3.0, 0.0]
    cells = [(r, c) for r in range(2) for c in range(3)]
    epss = 10.0 ** -np.arange(3, 39)
    pairs = [(eps, name, p) for eps in epss for phi in (0.0, 2.3) for name, p in _near_pairs(eps, phi).items()]
    pairs += [(0.0, "exact normal", ([0.0, 0.0, 1.0], [0.0, 0.0, 1.0]))]
    lanes = [(cell, pair) for cell in cells for pair in pairs]
    n = len(lanes)
    wi = np.array([p[2][0] for _, p in lanes], np.float32)
    wo = np.array([p[2][1] for _, p in lanes], np.float32)
    si = dr.zeros(mi.SurfaceInteraction3f, n)
    si.wi = mi.Vector3f(*(mi.Float(c) for c in wi.T))
    si.uv = mi.Point2f(mi.Float(np.array([(c + 0.5) / 3 for (r, c), _ in lanes], np.float32)),
                       mi.Float(np.array([(r + 0.5) / 2 for (r, c), _ in lanes], np.float32)))
    si.wavelengths = mi.UnpolarizedSpectrum(450.0, 550.0, 650.0, 750.0)
    wo_v = mi.Vector3f(*(mi.Float(c) for c in wo.T))
    s1 = mi.Float(np.linspace(0.01, 0.99, n).astype(np.float32))
    s2 = mi.Point2f(mi.Float(np.linspace(0.02, 0.98, n).astype(np.float32)), mi.Float(np.full(n, 0.5, np.float32)))

    def bitmap(rows):
        return {"type": "bitmap", "raw": True, "filter_type": "nearest",
                "data": mi.TensorXf(np.asarray(rows, np.float32)[..., None])}

    def textures():       # a fresh dict per load: the loader takes the tensors over
        return {"rms_slope": bitmap([roughs, roughs]), "eta": bitmap([[e] * 3 for e in etas]),
                "k": bitmap([[k] * 3 for k in ks])}
    near = np.array([name.startswith(("wi normal", "wo normal")) and eps <= 1e-6 for _, (eps, name, _) in lanes])
    exact = {cell: i for i, (cell, (_, name, _)) in enumerate(lanes) if name == "exact normal"}
    for shadowing, diffuse, visible in (("vgroove", "paper", True), ("smith", "reciprocal", False),
                                        ("none", "paper", True), ("smith", "none", True)):
        b = mi.load_dict({"type": "hyde", "shadowing": shadowing, "diffuse": diffuse, "sample_visible": visible,
                          **textures()})
        for mode in (mi.TransportMode.Radiance, mi.TransportMode.Importance):
            ctx = mi.BSDFContext(mode)
            v, p = b.eval_pdf(ctx, si, wo_v)
            bs, w = b.sample(ctx, si, s1, s2)
            for x in (v, p, w, bs.pdf):
                assert _finite(x), (shadowing, diffuse, mode)
            assert float(dr.min(p)[0]) >= 0.0
            v = np.asarray(v, dtype=float)
            for i, (cell, _) in enumerate(lanes):
                if near[i] and roughs[cell[1]] == 0.3:
                    ref = v[..., exact[cell]]
                    assert np.abs(v[..., i] - ref).max() <= 1e-5 * np.abs(ref).max(), (cell, shadowing, mode)
