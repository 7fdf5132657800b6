"""The plugin's inputs as Mitsuba evaluates them, and updates that cannot half-apply (issue 15).

Checked:

* texture values are validated as ``eval`` returns them, not as stored: an 8-bit PNG roughness
  map (raw or sRGB; stored 0-255 in non-spectral variants) loads in every kind of variant, like
  roughconductor, and gives the BSDF of the roughness its texel evaluates to (relative <= 1e-6
  against a constant of that value);
* negative, non-finite or too large (> 1e6) texels of ``eta``, ``k`` and ``specular_reflectance``
  are refused naming the parameter, as constants are;
* alpha = 0 (a constant or a texel) renders as the lower bound with one warning (roughconductor's
  mirror limit), the printed bounds are accepted, and ``material="none"`` is roughconductor's
  spelling of "eta and k given";
* values that cannot be read at load (a ``mesh_attribute``) are clamped at evaluation: NaN,
  negative and huge vertex values give finite values and a white-furnace albedo <= 1;
* a refused ``params.update()`` leaves the BSDF as it was (constant, bitmap and index keys).
"""
import math
import warnings

import numpy as np
import pytest

from hyde_bsdf.mitsuba.variants import set_variant
from conftest import mitsuba_with_hyde

ALL_KINDS = ["scalar_rgb", "llvm_ad_rgb", "llvm_ad_mono_polarized", "llvm_ad_spectral_polarized"]



def _si(mi, uv, wi=(0.3, 0.1, 0.95)):
    import drjit as dr

    si = dr.zeros(mi.SurfaceInteraction3f)
    si.wi = dr.normalize(mi.Vector3f(*wi))
    si.uv = mi.Point2f(*uv)
    if mi.is_spectral:
        si.wavelengths = mi.UnpolarizedSpectrum(450.0, 550.0, 600.0, 650.0)
    return si


def _eval(mi, bsdf, si, wo=(-0.2, -0.1, 0.97)):
    import drjit as dr

    v = bsdf.eval(mi.BSDFContext(), si, dr.normalize(mi.Vector3f(*wo)))
    return np.asarray(v, dtype=float).ravel()


@pytest.fixture(scope="module")
def png(tmp_path_factory):
    """A 2 x 2 8-bit grey PNG: texels 30, 83 / 200, 255 (alpha 0.118 ... 1 when read raw)."""
    import mitsuba as mi

    set_variant("scalar_rgb", fallback=False)
    path = tmp_path_factory.mktemp("png") / "rough8.png"
    mi.Bitmap(np.array([[30, 83], [200, 255]], np.uint8)[..., None]).write(str(path))
    return str(path)


@pytest.mark.parametrize("variant", ALL_KINDS)
@pytest.mark.parametrize("raw", [True, False])
def test_8bit_png_roughness_is_checked_and_used_as_eval_returns_it(variant, raw, png):
    mi = mitsuba_with_hyde(variant)
    tex = {"type": "bitmap", "filename": png, "raw": raw, "filter_type": "nearest"}
    bsdf = mi.load_dict({"type": "hyde", "alpha": tex, "material": "Au", "diffuse": "none",
                         "shadowing": "smith"})
    rough = mi.load_dict({"type": "roughconductor", "alpha": tex, "material": "Au"})
    texture = mi.load_dict(tex)
    si = _si(mi, (0.75, 0.25))                         # the texel holding 83
    alpha = float(np.asarray(texture.eval_1(si)).ravel()[0])
    expected = 83 / 255 if raw else ((83 / 255 + 0.055) / 1.055) ** 2.4
    assert alpha == pytest.approx(expected, rel=2e-3)
    const = mi.load_dict({"type": "hyde", "alpha": alpha, "material": "Au", "diffuse": "none", "shadowing": "smith"})
    got, ref = _eval(mi, bsdf, si), _eval(mi, const, si)
    assert np.abs(got - ref).max() <= 1e-6 * np.abs(ref).max()
    # the model coincides with roughconductor here (smith, no diffuse term): same texel, same value
    assert np.abs(_eval(mi, rough, si) - ref).max() <= 2e-5 * np.abs(ref).max()


@pytest.mark.parametrize("variant", ["scalar_rgb", "llvm_ad_rgb", "llvm_ad_mono_polarized", "llvm_ad_spectral_polarized"])
@pytest.mark.parametrize("name,texel,needle", [
    ("eta", -1.5, "'eta' must be finite and in [0, 1e+06]"),
    ("k", float("nan"), "'k' (k.data) contains NaN"),
    ("k", 3e7, "'k' must be finite and in [0, 1e+06]"),
    ("specular_reflectance", -0.5, "'specular_reflectance' must be finite and >= 0"),
])
def test_bad_texels_of_the_index_and_scale_are_refused(variant, name, texel, needle):
    mi = mitsuba_with_hyde(variant)
    data = np.full((3, 3, 1), 1.5 if name == "eta" else 0.5, np.float32)
    data[1, 2, 0] = texel
    tex = {"type": "bitmap", "raw": True, "data": mi.TensorXf(data)}
    props = {"type": "hyde", "rms_slope": 0.3, "eta": 1.5, "k": 0.0, name: tex}
    with pytest.raises(Exception) as exc:
        mi.load_dict(props)
    assert needle in str(exc.value), str(exc.value)[-300:]


def test_alpha_zero_renders_as_the_lower_bound_with_one_warning():
    mi = mitsuba_with_hyde("llvm_ad_rgb")
    from hyde_bsdf.model.parameters import ALPHA

    si = _si(mi, (0.25, 0.25), wi=(0.3, 0.0, 0.954))
    ref = _eval(mi, mi.load_dict({"type": "hyde", "alpha": ALPHA.lo, "material": "Au"}), si, wo=(-0.3, 0.0, 0.954))
    for alpha in (0.0, {"type": "bitmap", "raw": True, "filter_type": "nearest",
                        "data": mi.TensorXf(np.array([[0.0, 0.3]], np.float32)[..., None])}):
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            b = mi.load_dict({"type": "hyde", "alpha": alpha, "material": "Au"})
        msgs = [str(w.message) for w in caught if "hyde:" in str(w.message)]
        assert len(msgs) == 1 and "floored to 0.0001414214" in msgs[0], msgs
        got = _eval(mi, b, si, wo=(-0.3, 0.0, 0.954))
        assert np.isfinite(got).all() and np.abs(got - ref).max() <= 1e-6 * np.abs(ref).max()
    # the bounds the messages print are accepted as they are printed, without a warning
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        for value in (0.0001414214, 70.71068):
            mi.load_dict({"type": "hyde", "alpha": value})
    rough = mi.load_dict({"type": "roughconductor", "alpha": 0.0, "material": "Au"})  # roughconductor loads it too
    assert rough is not None


def test_material_none_is_roughconductors_spelling():
    mi = mitsuba_with_hyde("llvm_ad_rgb")
    si = _si(mi, (0.5, 0.5))
    default = _eval(mi, mi.load_dict({"type": "hyde"}), si)
    assert np.array_equal(_eval(mi, mi.load_dict({"type": "hyde", "material": "none"}), si), default)
    glass = _eval(mi, mi.load_dict({"type": "hyde", "material": "none", "eta": 1.5, "k": 0.0}), si)
    assert np.array_equal(glass, _eval(mi, mi.load_dict({"type": "hyde", "eta": 1.5, "k": 0.0}), si))


def _quad_ply(path, r, e):
    """A binary PLY quad (z = 0, 2 x 2) with per-vertex attributes r and e (NaN allowed)."""
    head = ("ply\nformat binary_little_endian 1.0\nelement vertex 4\n"
            + "".join(f"property float {c}\n" for c in ("x", "y", "z", "u", "v", "r", "e"))
            + "element face 2\nproperty list uchar int vertex_indices\nend_header\n").encode()
    xy = [(-1, -1), (1, -1), (1, 1), (-1, 1)]
    verts = np.array([[x, y, 0.0, (x + 1) / 2, (y + 1) / 2, r[i], e[i]] for i, (x, y) in enumerate(xy)], "<f4")
    faces = b"".join(np.uint8(3).tobytes() + np.array(f, "<i4").tobytes() for f in ((0, 1, 2), (0, 2, 3)))
    path.write_bytes(head + verts.tobytes() + faces)


def test_mesh_attribute_values_are_clamped_at_eval_never_nan_never_energy_gain(tmp_path):
    import drjit as dr

    mi = mitsuba_with_hyde("llvm_ad_spectral_polarized")
    path = tmp_path / "quad.ply"
    _quad_ply(path, r=[math.nan, -1.0, 1e9, 0.3], e=[-1.5, math.nan, 1e12, 1.5])
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        scene = mi.load_dict({"type": "scene", "quad": {
            "type": "ply", "filename": str(path),
            "bsdf": {"type": "hyde", "rms_slope": {"type": "mesh_attribute", "name": "vertex_r"},
                     "eta": {"type": "mesh_attribute", "name": "vertex_e"}, "k": 0.0}}})
    msgs = [str(w.message) for w in caught if "cannot be read at load" in str(w.message)]
    assert len(msgs) == 2 and "rms_slope" in msgs[0] and "eta" in msgs[1], msgs
    n = 64 * 64
    g = (np.arange(n) + 0.5) / n
    xs, ys = np.meshgrid(np.linspace(-0.99, 0.99, 64), np.linspace(-0.99, 0.99, 64))
    rays = mi.Ray3f(mi.Point3f(mi.Float(xs.ravel()), mi.Float(ys.ravel()), 1.0), mi.Vector3f(0.0, 0.0, -1.0))
    si = scene.ray_intersect(rays)
    si.wavelengths = mi.UnpolarizedSpectrum(450.0, 550.0, 600.0, 650.0)
    si.wi = dr.normalize(mi.Vector3f(0.4, 0.1, 0.9))
    bsdf = si.bsdf()
    ctx = mi.BSDFContext()
    albedo = np.zeros(n)
    rng = np.random.default_rng(1)
    for _ in range(64):                           # white furnace per point: E[weight M00] <= 1
        s1 = mi.Float(rng.uniform(0, 1, n).astype(np.float32))
        s2 = mi.Point2f(*(mi.Float(rng.uniform(0, 1, n).astype(np.float32)) for _ in range(2)))
        bs, w = bsdf.sample(ctx, si, s1, s2, si.is_valid())
        w = np.asarray(w, dtype=float)
        assert np.isfinite(w).all()
        albedo += np.asarray(w[0, 0], dtype=float).reshape(4, n).mean(0) if w.ndim == 4 else w[0]
        v, p = bsdf.eval_pdf(ctx, si, bs.wo, si.is_valid())
        assert np.isfinite(np.asarray(v, dtype=float)).all() and np.isfinite(np.asarray(p, dtype=float)).all()
    albedo /= 64
    assert float(np.asarray(si.is_valid()).mean()) > 0.99 and g.size == n
    assert albedo.max() <= 1.02, albedo.max()


@pytest.mark.parametrize("key,value", [("alpha.value", -0.2), ("alpha.value", float("nan")),
                                       ("eta.value", -1.0), ("k.value", 1e9),
                                       ("specular_reflectance.value", -1.0)])
def test_refused_update_leaves_the_bsdf_as_it_was(key, value):
    mi = mitsuba_with_hyde("llvm_ad_rgb")
    b = mi.load_dict({"type": "hyde", "alpha": 0.3, "eta": 0.5, "k": 3.0})
    si = _si(mi, (0.5, 0.5))
    before = _eval(mi, b, si)
    params = mi.traverse(b)
    old = np.asarray(params[key], dtype=float).copy()
    params[key] = value
    with pytest.raises(ValueError, match="hyde: "):
        params.update()
    assert np.array_equal(_eval(mi, b, si), before)
    assert np.array_equal(np.asarray(mi.traverse(b)[key], dtype=float), old)
    params[key] = 0.4 if key.startswith("alpha") else old[0]      # a good value is taken afterwards
    params.update()
    if key.startswith("alpha"):
        assert not np.array_equal(_eval(mi, b, si), before)


def test_refused_bitmap_update_restores_every_texel():
    mi = mitsuba_with_hyde("llvm_ad_rgb")
    data = np.full((2, 3, 1), 0.3, np.float32)
    data[0, 1, 0] = 0.6
    b = mi.load_dict({"type": "hyde", "rms_slope": {"type": "bitmap", "raw": True, "filter_type": "nearest",
                                                    "data": mi.TensorXf(data)}})
    si = _si(mi, (0.5, 0.25))
    before = _eval(mi, b, si)
    params = mi.traverse(b)
    bad = data.copy()
    bad[0, 1, 0] = math.inf
    params["rms_slope.data"] = mi.TensorXf(bad)
    with pytest.raises(ValueError, match="rms_slope"):
        params.update()
    assert np.array_equal(np.asarray(mi.traverse(b)["rms_slope.data"]), data)
    assert np.array_equal(_eval(mi, b, si), before)


@pytest.mark.parametrize("raw", [True, False])
def test_update_checks_read_an_8bit_png_through_eval_and_a_float_bitmap_from_its_data(raw, png):
    """An update is checked on the values ``eval`` returns.  A float bitmap (eval = data) is read
    from its data after the first check, with no kernel launched, and bad texels are still refused
    naming the texel; an 8-bit PNG's data (0-255) is never taken for its values (texel 200 is
    alpha 0.78 raw, 0.58 sRGB-decoded: accepted, although 200 is outside [0, 70.71])."""
    import drjit as dr

    mi = mitsuba_with_hyde("llvm_ad_mono_polarized")
    png_tex = {"type": "bitmap", "filename": png, "raw": raw, "filter_type": "nearest"}
    params = mi.traverse(mi.load_dict({"type": "hyde", "alpha": png_tex, "material": "Au"}))
    for _ in range(2):
        params["alpha.data"] = mi.TensorXf(np.array([[30, 83], [200, 201]], np.float32)[..., None])
        params.update()                                # accepted: values 0.12 .. 0.79 (raw)
    data = np.array([[0.1, 0.2], [0.3, 0.4]], np.float32)[..., None]
    params = mi.traverse(mi.load_dict({"type": "hyde", "alpha": {"type": "bitmap", "raw": True,
                                                                 "data": mi.TensorXf(data)}}))
    params["alpha.data"] = mi.TensorXf(data * 2)
    params.update()                                    # the first check: through eval, one kernel
    new = mi.TensorXf(data * 3)
    dr.eval(new)
    dr.set_flag(dr.JitFlag.KernelHistory, True)
    dr.kernel_history()
    params["alpha.data"] = new
    params.update()
    kernels = [h for h in dr.kernel_history() if str(h["type"]).endswith("JIT")]
    dr.set_flag(dr.JitFlag.KernelHistory, False)
    assert kernels == []
    for texel, needle in ((80.0, "alpha.data texel value 80.0 (1 of 4 values read)"),
                          (float("nan"), "(alpha.data) contains NaN")):
        bad = data * 3
        bad[1, 0, 0] = texel
        params["alpha.data"] = mi.TensorXf(bad)
        with pytest.raises(ValueError) as exc:
            params.update()
        assert needle in str(exc.value), str(exc.value)
        # a refused update leaves the accepted values
        np.testing.assert_allclose(np.asarray(params["alpha.data"]), data * 3, rtol=1e-7)
