"""Sampling of the ``hyde`` plugin: chi^2 tests and sample/eval/pdf consistency.

Physics checked: the directions ``sample`` draws (visible-normal Beckmann sampling
of the specular lobe -- the V-cavity's visible normals with V-groove shadowing, Smith's otherwise -- mixed with
cosine sampling of the diffuse lobe) follow the
density ``pdf`` reports - Mitsuba's chi^2 test on the sphere (``mitsuba.chi2``,
with the polarization-aware adapter ``hyde_bsdf.validation._chi2``) at 13 (rms_slope,
theta_i) configurations spanning rms_slope 0.02-1.5 and theta_i 0-85 deg, for
several shadowing/diffuse/sample_visible settings, in an unpolarized and a
polarized LLVM variant; and the returned Mueller weight is eval/pdf.

Sample counts are kept modest for CI (1e6 samples, 128 x 64 cells, 8x8 pdf
integration per cell); all tests at one Sidak-corrected 1 % significance level.
"""
import math

import numpy as np
import pytest

from conftest import mitsuba_with_hyde

CONFIGS = [(0.02, 30), (0.02, 60), (0.05, 0), (0.05, 45), (0.1, 0), (0.1, 85), (0.3, 45),
           (0.3, 80), (0.6, 10), (0.6, 70), (1.0, 30), (1.5, 0), (1.5, 85)]
MODELS = {  # (shadowing, diffuse, sample_visible)
    "llvm_ad_rgb": [("vgroove", "paper", True), ("smith", "none", True), ("none", "paper", True)],
    "llvm_ad_spectral_polarized": [("vgroove", "paper", True), ("vgroove", "reciprocal", False),
                                   ("smith", "paper", True)],
}
CASES = [(v, m, c) for v, ms in MODELS.items() for m in ms for c in CONFIGS]
#: issue 30: the Lambertian term (albedo 0.3), its own choice of lobe (p_spec from the albedo), at 3 configurations
CASES += [("llvm_ad_rgb", ("smith", "lambertian", True), c) for c in ((0.02, 30), (0.3, 80), (1.0, 30))]
#: the V-cavity's visible normals alone (the specular lobe's own sampling routine, without the lobe choice)
CASES += [("llvm_ad_rgb", ("vgroove", "none", True), c) for c in ((0.02, 60), (0.3, 80), (1.0, 30), (1.5, 85))]



@pytest.mark.parametrize("variant,model,config", CASES,
                         ids=[f"{v}-{m[0]}-{m[1]}-{'vis' if m[2] else 'all'}-{c[0]}-{c[1]}deg"
                              for v, m, c in CASES])
def test_chi2(variant, model, config):
    from hyde_bsdf.validation._chi2 import chi2_test

    mi = mitsuba_with_hyde(variant)
    shadowing, diffuse, visible = model
    rms, theta_deg = config
    bsdf = mi.load_dict({"type": "hyde", "rms_slope": rms, "material": "Au", "shadowing": shadowing,
                         "diffuse": diffuse, "sample_visible": visible,
                         **({"diffuse_reflectance": 0.3} if diffuse == "lambertian" else {})})
    passed, p_value, messages = chi2_test(bsdf, math.radians(theta_deg), sample_count=1_000_000,
                                          res=128, ires=8, test_count=len(CASES))
    assert passed, messages


@pytest.mark.parametrize("mode,diffuse,visible", [("radiance", "paper", True),
                                                   ("importance", "paper", False),
                                                   ("radiance", "none", True),
                                                   ("importance", "none", False)])
def test_weight_is_eval_over_pdf_polarized(mode, diffuse, visible):
    """sample() returns wo, pdf(wo) and the full Mueller weight eval(wo)/pdf(wo)."""
    import drjit as dr

    mi = mitsuba_with_hyde("llvm_ad_spectral_polarized")
    bsdf = mi.load_dict({"type": "hyde", "rms_slope": 0.4, "material": "Al", "diffuse": diffuse,
                         "sample_visible": visible})
    n = 20_000
    rng = np.random.default_rng(4)
    ctx = mi.BSDFContext(mi.TransportMode.Radiance if mode == "radiance" else mi.TransportMode.Importance)
    si = dr.zeros(mi.SurfaceInteraction3f)
    z = rng.uniform(0.05, 1, n)
    phi = rng.uniform(0, 2 * np.pi, n)
    wi = np.stack([np.sqrt(1 - z * z) * np.cos(phi), np.sqrt(1 - z * z) * np.sin(phi), z])
    si.wi = mi.Vector3f(*(mi.Float(w.astype(np.float32)) for w in wi))
    si.wavelengths = mi.UnpolarizedSpectrum(550.0)
    s1 = mi.Float(rng.random(n).astype(np.float32))
    s2 = mi.Point2f(*(mi.Float(rng.random(n).astype(np.float32)) for _ in range(2)))
    bs, weight = bsdf.sample(ctx, si, s1, s2)
    value, pdf = bsdf.eval_pdf(ctx, si, bs.wo)
    pdf_only = bsdf.pdf(ctx, si, bs.wo)
    dr.eval(bs, weight, value, pdf, pdf_only)
    ok = np.array(bs.pdf) > 0
    assert ok.mean() > (0.9 if visible else 0.6)   # all-normal sampling wastes more
    comp = np.broadcast_to(np.array(bs.sampled_component), (n,))[ok]
    if diffuse != "none":   # both lobes are used
        assert 0.05 < (comp == 1).mean() < 0.95
    else:
        assert (comp == 0).all()
    # sample() uses the sampled normal m, pdf() the recomputed h = normalize(wi + wo): float32
    # noise, up to 1.6e-5 at grazing wo (roughconductor's own sample/pdf differ identically)
    assert np.allclose(np.array(bs.pdf)[ok], np.array(pdf)[ok], rtol=5e-5)
    assert np.allclose(np.array(pdf_only)[ok], np.array(pdf)[ok], rtol=1e-6)
    W = np.stack([np.stack([np.array(weight[r, c])[0][ok] for c in range(4)], -1) for r in range(4)], -2)
    F = np.stack([np.stack([np.array(value[r, c])[0][ok] for c in range(4)], -1) for r in range(4)], -2)
    F = F / np.array(pdf)[ok][:, None, None]
    # per matrix, relative to its largest element (the m-vs-h float32 noise above)
    scale = np.abs(F).max(axis=(-2, -1), keepdims=True)
    assert (np.abs(W - F) <= 1e-4 * scale + 1e-7).all(), np.max(np.abs(W - F) / scale)


def test_vcavity_visible_normals_bound_the_weight_by_fresnel():
    """V-groove shadowing samples the visible normals of the V-cavity model (Heitz & d'Eon 2014): the density
    D G1(wi, m) wi.m / cos theta_i with the V-cavity's G1, whose minimum over wi and wo is Eq. 12's G, so the
    weight f cos theta_o / pdf = G F / G1(wi) <= F.  A perfect conductor (F = 1): every weight <= 1 (float32),
    at rms_slope 0.05-2 and theta_i 0-89.5 deg, where Smith's visible normals (the sampler before) gave weights
    above 1 near grazing incidence (G_V-groove / G1_Smith(wi) > 1); the mean weight is the lobe's albedo,
    <= 1, and the chosen faces look at wi (wi.m > 0)."""
    import drjit as dr

    mi = mitsuba_with_hyde("llvm_ad_rgb")
    rng = np.random.default_rng(7)
    n = 50_000
    for rms in (0.05, 0.3, 1.0, 2.0):
        bsdf = mi.load_dict({"type": "hyde", "rms_slope": rms, "eta": 0.0, "k": 1e4, "diffuse": "none"})
        for theta in (0.0, 40.0, 75.0, 89.5):
            t = math.radians(theta)
            si = dr.zeros(mi.SurfaceInteraction3f)
            si.wi = mi.Vector3f(math.sin(t), 0.0, math.cos(t))
            s1 = mi.Float(rng.random(n).astype(np.float32))
            s2 = mi.Point2f(*(mi.Float(rng.random(n).astype(np.float32)) for _ in range(2)))
            bs, weight = bsdf.sample(mi.BSDFContext(), si, s1, s2)
            w = np.array(weight)[0]
            assert w.max() <= 1.0 + 1e-5, (rms, theta, w.max())
            assert 0.0 < w.mean() <= 1.0, (rms, theta, w.mean())    # the albedo (failed samples weigh 0)
            m = np.array(dr.normalize(bs.wo + si.wi))[:, np.array(bs.pdf) > 0]
            assert (np.array(si.wi)[:, :1] * m).sum(0).min() > 0
