"""Property test (Hypothesis) of the plugin's ``eval`` / ``pdf`` / ``sample`` at random and edge inputs.

Inputs include directions at, just above and below the horizon, normal and grazing incidence,
rms_slope (or alpha) at the ends of the accepted range and beyond it, k = 0 (dielectrics) up to
1e7, eta = 0, every shadowing/diffuse switch, both transport modes and sample values at 0 and
just below 1.  The property: a parameter outside the accepted range is refused at load with a
``ValueError`` naming it; everything else gives finite values (never NaN or Inf), pdf >= 0, and
a sample weight that is finite and zero where the pdf is.
"""
import math

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
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


@settings(max_examples=250, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(rough=ROUGH, spelling=st.sampled_from(["rms_slope", "alpha"]), eta=ETAS, k=KS,
       shadowing=st.sampled_from(["vgroove", "smith", "none"]),
       diffuse=st.sampled_from(["paper", "reciprocal", "none"]), visible=st.booleans(),
       ti=THETAS, pi=PHIS, to=THETAS, po=PHIS, s1=UNIT, s2a=UNIT, s2b=UNIT,
       importance=st.booleans())
def test_eval_pdf_sample_finite_or_refused(rough, spelling, eta, k, shadowing, diffuse, visible,
                                           ti, pi, to, po, s1, s2a, s2b, importance):
    import mitsuba as mi
    import hyde_bsdf

    set_variant("scalar_spectral_polarized", fallback=False)
    hyde_bsdf.register("scalar_spectral_polarized")
    from hyde_bsdf.mitsuba.plugin import ALPHA_RANGE, RMS_RANGE, plugin_class

    lo, hi = RMS_RANGE if spelling == "rms_slope" else ALPHA_RANGE
    props = mi.Properties("hyde")
    props[spelling] = rough
    props["eta"], props["k"] = eta, k
    props["shadowing"], props["diffuse"], props["sample_visible"] = shadowing, diffuse, visible
    # textures hold float32: an index that rounds to 0 is 0
    invalid = (not lo * (1 - 1e-6) <= rough <= hi * (1 + 1e-6)) or k < 0 \
        or (np.float32(eta) == 0 and np.float32(k) == 0) \
        or (diffuse == "reciprocal" and shadowing == "none")
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
        for eta, k in ((1.5, 0.0), (0.0, 1e7), (0.285, 7.35)):
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
