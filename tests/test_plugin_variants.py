"""Variants: CUDA without a device gives a message naming the CPU variant; with a device the
plugin runs in a ``cuda_*`` variant and agrees with the LLVM one (the only tests skipped
elsewhere: they need an NVIDIA GPU)."""
import numpy as np
import pytest


def _has_cuda():
    import drjit as dr

    return bool(dr.has_backend(dr.JitBackend.CUDA))


def test_register_never_fails_and_lists_only_usable_variants():
    import mitsuba as mi
    import hyde_bsdf
    from hyde_bsdf.mitsuba.variants import usable_variants

    done = hyde_bsdf.register()
    assert done == usable_variants()
    assert all(v in mi.variants() for v in done)
    assert any(v.startswith("cuda_") for v in done) == _has_cuda()


@pytest.mark.skipif(_has_cuda(), reason="checks the message given where no CUDA device exists")
def test_cuda_variant_without_device_says_what_to_do():
    import mitsuba as mi
    import hyde_bsdf
    from hyde_bsdf.mitsuba.variants import VariantUnavailable, set_variant

    before = mi.variant()
    for call in (lambda: hyde_bsdf.register("cuda_ad_spectral_polarized"),
                 lambda: set_variant("cuda_ad_spectral_polarized", fallback=False)):
        with pytest.raises(VariantUnavailable) as exc:
            call()
        msg = str(exc.value)
        assert "CUDA" in msg and "llvm_ad_spectral_polarized" in msg, msg
    assert mi.variant() == before
    with pytest.warns(RuntimeWarning, match="llvm_ad_rgb"):
        assert set_variant("cuda_ad_rgb") == "llvm_ad_rgb"


def _eval(mi, params, n=400, seed=0):
    import drjit as dr

    rng = np.random.default_rng(seed)

    def hemi():
        z = rng.uniform(0.1, 1, n)
        ph = rng.uniform(0, 2 * np.pi, n)
        r = np.sqrt(1 - z * z)
        return mi.Vector3f(*(mi.Float(a.astype(np.float32)) for a in (r * np.cos(ph), r * np.sin(ph), z)))

    si = dr.zeros(mi.SurfaceInteraction3f, n)
    si.wi = hemi()
    si.uv = mi.Point2f(mi.Float(rng.uniform(0, 1, n).astype(np.float32)),
                       mi.Float(rng.uniform(0, 1, n).astype(np.float32)))
    si.wavelengths = mi.UnpolarizedSpectrum(550.0)
    v = mi.load_dict(params).eval(mi.BSDFContext(), si, hemi())
    return np.stack([np.stack([np.asarray(v[r, c])[0] for c in range(4)], -1) for r in range(4)], -2)


@pytest.mark.skipif(not _has_cuda(), reason="needs an NVIDIA GPU (cuda_* variants)")
def test_cuda_variant_matches_llvm():
    import mitsuba as mi
    import hyde_bsdf
    from hyde_bsdf.mitsuba.variants import set_variant

    results = []
    for variant in ("llvm_ad_spectral_polarized", "cuda_ad_spectral_polarized"):
        set_variant(variant, fallback=False)
        hyde_bsdf.register(variant)
        tex = {"type": "checkerboard", "color0": 0.2, "color1": 0.6}
        results.append(_eval(mi, {"type": "hyde", "alpha": tex, "material": "Au", "diffuse": "reciprocal"}))
    ref = results[0]
    assert np.isfinite(results[1]).all()
    assert np.abs(results[1] - ref).max() <= 2e-5 * np.abs(ref).max()
