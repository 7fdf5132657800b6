"""Texture-valued roughness, the user's spelling of the traverse keys, update validation.

Physics checked: a roughness texture is the roughness *at the shading point* (a bitmap
or checkerboard texel gives the same Mueller matrix as a uniform surface of that
roughness, the diffuse term's DHR lookup included); a constant texture is the float
(<= 1e-6); ``alpha`` keys carry Beckmann alpha (roughconductor's meaning); gradients
reach each texel (AD against central finite differences per texel);
``specular_reflectance`` scales the BSDF linearly.
"""
import math

import numpy as np
import pytest

from conftest import mitsuba_with_hyde



def _bitmap(mi, values, filter_type="bilinear"):
    data = np.asarray(values, np.float32)[..., None]
    return {"type": "bitmap", "raw": True, "filter_type": filter_type, "data": mi.TensorXf(data)}


def _si(mi, n, seed, uv=None, zmin=0.15):
    """n direction pairs (wi in si, wo) with the given uv (or random uv), at 550 nm."""
    import drjit as dr

    rng = np.random.default_rng(seed)

    def hemi():
        z = rng.uniform(zmin, 1, n)
        ph = rng.uniform(0, 2 * np.pi, n)
        r = np.sqrt(1 - z * z)
        return [mi.Float(a.astype(np.float32)) for a in (r * np.cos(ph), r * np.sin(ph), z)]

    si = dr.zeros(mi.SurfaceInteraction3f, n)
    si.wi = mi.Vector3f(*hemi())
    uv = rng.uniform(0.02, 0.98, (n, 2)) if uv is None else np.broadcast_to(np.asarray(uv, float), (n, 2))
    si.uv = mi.Point2f(mi.Float(uv[:, 0].astype(np.float32)), mi.Float(uv[:, 1].astype(np.float32)))
    if mi.is_spectral:
        si.wavelengths = mi.UnpolarizedSpectrum(550.0)
    return si, mi.Vector3f(*hemi()), uv


def _mueller(mi, v):
    """eval result -> float64 [n, 4, 4] (polarized, first wavelength) or [n, channels]."""
    if mi.is_polarized:
        return np.stack([np.stack([np.asarray(v[r, c])[0] for c in range(4)], -1) for r in range(4)], -2)
    return np.asarray(v).T


def _eval(mi, bsdf, si, wo):
    import drjit as dr

    v = bsdf.eval(mi.BSDFContext(), si, wo)
    dr.eval(v)
    return _mueller(mi, v)


VARIANTS = ["llvm_ad_spectral_polarized", "llvm_ad_rgb"]


@pytest.mark.parametrize("variant", VARIANTS)
@pytest.mark.parametrize("key", ["rms_slope", "alpha"])
def test_constant_textures_equal_the_float(variant, key):
    mi = mitsuba_with_hyde(variant)
    si, wo, _ = _si(mi, 3000, 1)
    base = {"type": "hyde", "material": "Au", "diffuse": "reciprocal"}
    ref = _eval(mi, mi.load_dict({**base, key: 0.3}), si, wo)
    for tex in (_bitmap(mi, np.full((3, 5), 0.3)),
                {"type": "checkerboard", "color0": 0.3, "color1": 0.3},
                {"type": "uniform", "value": 0.3}):
        got = _eval(mi, mi.load_dict({**base, key: tex}), si, wo)
        assert np.abs(got - ref).max() <= 1e-6 * np.abs(ref).max(), (key, tex["type"])


@pytest.mark.parametrize("variant", VARIANTS + ["scalar_spectral_polarized"])
def test_bitmap_and_checkerboard_give_the_roughness_of_the_texel(variant):
    """Each half of a 2x1 nearest-filtered bitmap, each checker square, is its own surface."""
    import drjit as dr

    mi = mitsuba_with_hyde(variant)
    base = {"type": "hyde", "eta": 0.4, "k": 3.5, "diffuse": "paper"}
    cases = [("rms_slope", _bitmap(mi, [[0.1, 0.6]], "nearest"), {(0.25, 0.5): 0.1, (0.75, 0.5): 0.6}),
             ("alpha", {"type": "checkerboard", "color0": 0.2, "color1": 0.5},
              {(0.75, 0.25): 0.2, (0.25, 0.25): 0.5, (0.75, 0.75): 0.5})]
    for key, tex, where in cases:
        textured = mi.load_dict({**base, key: tex})
        for uv, value in where.items():
            uniform = mi.load_dict({**base, key: value})
            if dr.is_jit_v(mi.Float):
                si, wo, _ = _si(mi, 500, 2, uv=uv)
                got, want = _eval(mi, textured, si, wo), _eval(mi, uniform, si, wo)
            else:   # scalar: a few single evaluations
                got, want = [], []
                rng = np.random.default_rng(3)
                for _ in range(20):
                    si = dr.zeros(mi.SurfaceInteraction3f)
                    a, b = rng.uniform(0.2, 1.0, 2)
                    si.wi = mi.Vector3f(math.sqrt(1 - a * a), 0.0, a)
                    si.uv = mi.Point2f(*uv)
                    si.wavelengths = mi.UnpolarizedSpectrum(550.0)
                    wo = mi.Vector3f(-0.3 * math.sqrt(1 - b * b), 0.95 * math.sqrt(1 - b * b), b)
                    wo = dr.normalize(wo)
                    got.append(np.asarray(textured.eval(mi.BSDFContext(), si, wo)[0, 0])[0])
                    want.append(np.asarray(uniform.eval(mi.BSDFContext(), si, wo)[0, 0])[0])
                got, want = np.array(got), np.array(want)
            assert np.abs(got - want).max() <= 1e-6 * np.abs(want).max(), (key, uv)


def test_keys_follow_the_scene_spelling_and_update_like_a_fresh_load():
    mi = mitsuba_with_hyde("llvm_ad_spectral_polarized")
    si, wo, _ = _si(mi, 1000, 4)
    b = mi.load_dict({"type": "hyde", "alpha": 0.3, "eta": 0.5, "k": 3.0})
    params = mi.traverse(b)
    assert {"alpha.value", "eta.value", "k.value", "specular_reflectance.value"} == set(params.keys())
    params["alpha.value"] = 0.6          # Beckmann alpha, as roughconductor's alpha.value
    params.update()
    fresh = mi.load_dict({"type": "hyde", "rms_slope": 0.6 / math.sqrt(2), "eta": 0.5, "k": 3.0})
    ref = _eval(mi, fresh, si, wo)
    assert np.abs(_eval(mi, b, si, wo) - ref).max() <= 2e-6 * np.abs(ref).max()
    tex = mi.load_dict({"type": "hyde", "rms_slope": _bitmap(mi, np.full((2, 2), 0.3)), "material": "Au"})
    keys = set(mi.traverse(tex).keys())
    assert {"rms_slope.data", "eta.values", "eta.wavelengths", "k.values", "k.wavelengths"} <= keys
    rgb = mitsuba_with_hyde("llvm_ad_rgb")
    keys = set(rgb.traverse(rgb.load_dict({"type": "hyde", "material": "Au"})).keys())
    assert {"rms_slope.value", "eta.value", "k.value"} <= keys


@pytest.mark.parametrize("key,value,words", [
    ("alpha.value", float("nan"), ["alpha", "range"]),
    ("alpha.value", 80.0, ["alpha", "range", "70.71"]),
    ("k.value", -1.0, ["k", ">= 0"]),
    ("eta.value", 0.0, ["eta", "k", "0"]),
])
def test_update_is_validated_as_at_load(key, value, words):
    mi = mitsuba_with_hyde("llvm_ad_rgb")
    b = mi.load_dict({"type": "hyde", "alpha": 0.3, "eta": 0.5, "k": 0.0 if key == "eta.value" else 3.0})
    params = mi.traverse(b)
    params[key] = value
    with pytest.raises(ValueError) as exc:
        params.update()
    for w in words:
        assert w in str(exc.value), (w, str(exc.value))


def test_update_of_bitmap_texels_is_validated():
    mi = mitsuba_with_hyde("llvm_ad_rgb")
    b = mi.load_dict({"type": "hyde", "rms_slope": _bitmap(mi, np.full((2, 3), 0.3))})
    params = mi.traverse(b)
    data = np.full((2, 3, 1), 0.3, np.float32)
    data[1, 2, 0] = -0.1
    params["rms_slope.data"] = mi.TensorXf(data)
    with pytest.raises(ValueError, match=r"rms_slope.*range.*rms_slope\.data texel value -0\.1.*1 of 6 values read"):
        params.update()
    with pytest.raises(Exception, match=r"rms_slope.*range"):
        mi.load_dict({"type": "hyde", "rms_slope": _bitmap(mi, [[0.3, -0.2]])})


@pytest.mark.parametrize("key,diffuse", [("rms_slope", "reciprocal"), ("alpha", "paper")])
def test_gradients_reach_each_texel(key, diffuse):
    """d loss / d texel of a bilinear 2x2 roughness bitmap: AD against central differences."""
    import drjit as dr

    mi = mitsuba_with_hyde("llvm_ad_spectral_polarized")
    x0 = np.array([[0.2, 0.35], [0.5, 0.8]]) * (math.sqrt(2) if key == "alpha" else 1.0)
    b = mi.load_dict({"type": "hyde", key: _bitmap(mi, x0), "eta": 0.5, "k": 3.0, "diffuse": diffuse})
    params = mi.traverse(b)
    si, wo, _ = _si(mi, 400, 5)
    dkey = f"{key}.data"

    def loss():
        v = b.eval(mi.BSDFContext(), si, wo)
        return dr.sum(v[0, 0][0] + 0.5 * v[2, 3][0] + 0.3 * v[1, 0][0])

    data = mi.TensorXf(x0.astype(np.float32)[..., None])
    dr.enable_grad(data)
    params[dkey] = data
    params.update()
    dr.backward(loss())
    grad = np.asarray(dr.grad(data)).reshape(2, 2)
    for i in range(2):
        for j in range(2):
            # 3e-3: smaller steps drown in the float32 rounding of the DHR texture coordinate
            h = 3e-3 * x0[i, j]
            vals = []
            for s in (1, -1):
                x = x0.copy()
                x[i, j] += s * h
                params[dkey] = mi.TensorXf(x.astype(np.float32)[..., None])
                params.update()
                vals.append(float(np.asarray(loss())[0]))
            fd = (vals[0] - vals[1]) / (2 * h)
            assert abs(fd) > 1e-2, (i, j, fd)
            assert abs(grad[i, j] - fd) <= 5e-3 * abs(fd), (key, i, j, grad[i, j], fd)


def test_specular_reflectance_scales_the_bsdf_and_is_differentiable():
    import drjit as dr

    mi = mitsuba_with_hyde("llvm_ad_spectral_polarized")
    si, wo, _ = _si(mi, 500, 6)
    one = mi.load_dict({"type": "hyde", "rms_slope": 0.3, "material": "Cu"})
    half = mi.load_dict({"type": "hyde", "rms_slope": 0.3, "material": "Cu", "specular_reflectance": 0.5})
    ref = _eval(mi, one, si, wo)
    assert np.abs(_eval(mi, half, si, wo) - 0.5 * ref).max() <= 1e-6 * np.abs(ref).max()
    params = mi.traverse(half)
    value = mi.Float(0.5)
    dr.enable_grad(value)
    params["specular_reflectance.value"] = value
    params.update()
    dr.backward(dr.sum(half.eval(mi.BSDFContext(), si, wo)[0, 0][0]))
    assert dr.grad(value)[0] == pytest.approx(ref[:, 0, 0].sum(), rel=1e-4)


def test_sigma_h_and_ell_stay_scalar_with_a_message_saying_so():
    mi = mitsuba_with_hyde("scalar_rgb")
    with pytest.raises(Exception, match="sigma_h and ell are scalars; give rms_slope or alpha for a texture"):
        mi.load_dict({"type": "hyde", "sigma_h": {"type": "checkerboard"}, "ell": 1.0})


def test_arrays_for_dr_jit_start_on_64_bytes_so_kernels_are_reused():
    """The DHR lookups and the validation's direction arrays hand Dr.Jit NumPy memory that starts on a 64-byte
    boundary (aligned_float32): Dr.Jit writes an input's alignment into the kernel, so arrays from NumPy's
    16-byte-aligned blocks made a new kernel (compiled again, missing the disk cache) whenever the address was
    not a multiple of 64 -- shown with the NumPy arrays themselves where the CPU makes that difference.  The same
    values; one kernel.  ~0.5 s."""
    import drjit as dr

    mi = mitsuba_with_hyde("llvm_ad_rgb")
    from hyde_bsdf.mitsuba.optics import aligned_float32

    def kernels(convert):
        dr.kernel_history()                                   # clear
        with dr.scoped_set_flag(dr.JitFlag.KernelHistory, True):
            for i in range(12):
                raw = np.empty(1001 + 16, np.float32)[i:i + 1001]   # NumPy memory at offsets of 4 i bytes
                raw[...] = np.linspace(0.0, 1.0, 1001)
                a = convert(raw)
                np.testing.assert_array_equal(a, raw)
                dr.eval(dr.sin(mi.Float(a)) * 2.0 + 1.0)
            return {k["hash"] for k in dr.kernel_history() if k["type"] == dr.KernelType.JIT}

    assert aligned_float32(np.ones((3, 5))).ctypes.data % 64 == 0 and aligned_float32(np.ones((3, 5))).shape == (3, 5)
    assert len(kernels(aligned_float32)) == 1
    # Unaligned memory makes an "align 1" variant beside "align 64" on this AVX-512 machine (2 kernels); on the CI
    # machine's CPU the two fell together (1 kernel).  Aligned arrays give one kernel on both.
    assert 1 <= len(kernels(lambda raw: raw)) <= 2
