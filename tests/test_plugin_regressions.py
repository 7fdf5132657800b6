"""Regressions found while integrating the plugin with rendering."""
import math

import numpy as np

import hyde_bsdf
from hyde_bsdf.mitsuba.variants import set_variant


def _sphere_scene(mi, bsdf):
    return mi.load_dict({
        "type": "scene", "integrator": {"type": "path", "max_depth": 3},
        "s": {"type": "sphere", "bsdf": bsdf}, "e": {"type": "constant"},
        "sensor": {"type": "perspective", "to_world": mi.ScalarTransform4f().look_at([0, -4, 0], [0, 0, 0], [0, 0, 1]),
                   "film": {"type": "hdrfilm", "width": 8, "height": 8}}})


def test_scalar_variant_samples_the_mixture():
    """scalar_* variants: the two-lobe sampler must not apply '~' to a Python bool (it gave -2)."""
    mi = __import__("mitsuba")
    set_variant("scalar_spectral_polarized")
    hyde_bsdf.register()
    bsdf = mi.load_dict({"type": "hyde", "rms_slope": 0.5, "material": "Au"})
    si = mi.SurfaceInteraction3f()
    si.wi = mi.Vector3f(0.3, 0.0, math.sqrt(1 - 0.09))
    si.wavelengths = mi.UnpolarizedSpectrum(550.0)
    kinds = set()
    for j in range(64):
        bs, w = bsdf.sample(mi.BSDFContext(), si, (j + 0.5) / 64, mi.Point2f(0.37, 0.61))
        assert np.all(np.isfinite(np.array(mi.unpolarized_spectrum(w))))
        kinds.add(int(bs.sampled_component))
    assert kinds == {0, 1}         # both lobes are sampled


def test_gradient_survives_repeated_backward_passes():
    """Derived quantities (alpha, the DHR coordinate) must not be cached: after dr.backward
    consumed the graph, the next pass must give the same gradient w.r.t. rms_slope."""
    import drjit as dr
    mi = __import__("mitsuba")
    set_variant("llvm_ad_rgb")
    hyde_bsdf.register()
    scene = _sphere_scene(mi, {"type": "hyde", "rms_slope": 0.3, "eta": 0.2, "k": 3.0})
    params = mi.traverse(scene)
    key = next(k for k in params.keys() if k.endswith("rms_slope.value"))
    dr.enable_grad(params[key])
    params.update()
    grads = []
    for _ in range(2):
        img = mi.render(scene, params, spp=4, seed=1)
        dr.backward(dr.mean(img, axis=None))
        grads.append(float(dr.ravel(dr.grad(params[key]))[0]))
        dr.set_grad(params[key], 0)
    assert grads[0] != 0.0
    assert abs(grads[1] - grads[0]) <= 1e-6 * abs(grads[0])


def test_smith_no_diffuse_renders_the_same_stokes_image_as_roughconductor():
    """hyde(shadowing=smith, diffuse=none) is roughconductor's model: with the same seed the two
    draw the same samples, so the Stokes images agree to float32 rounding, all four components."""
    import drjit as dr
    mi = __import__("mitsuba")
    set_variant("llvm_ad_spectral_polarized")
    hyde_bsdf.register()
    T = mi.ScalarTransform4f
    alpha = 0.35

    def scene(bsdf):
        return mi.load_dict({
            "type": "scene", "integrator": {"type": "stokes", "integrator": {"type": "path", "max_depth": 3}},
            "sensor": {"type": "perspective", "fov": 40,
                       "to_world": T().look_at(origin=[0, -5, 2.5], target=[0, 0, 0.5], up=[0, 0, 1]),
                       "film": {"type": "hdrfilm", "width": 24, "height": 16, "pixel_format": "rgb"}},
            "sun": {"type": "directional", "direction": [0.5, -0.6, -0.6]},
            "sky": {"type": "constant", "radiance": {"type": "rgb", "value": 0.2}},
            "ball": {"type": "sphere", "center": [0, 0, 0.8], "radius": 0.8, "bsdf": bsdf},
            "floor": {"type": "rectangle", "to_world": T().scale(6.0), "bsdf": bsdf}})

    idx = {"material": "Au"}
    a = np.array(mi.render(scene({"type": "roughconductor", "distribution": "beckmann", "alpha": alpha, **idx}),
                           spp=8, seed=3))
    b = np.array(mi.render(scene({"type": "hyde", "alpha": alpha, "shadowing": "smith", "diffuse": "none", **idx}),
                           spp=8, seed=3))
    dr.sync_thread()
    scale = np.abs(a[..., 3:6]).max()
    assert scale > 0
    assert np.abs(b - a).max() <= 1e-5 * scale      # measured 3.6e-7


def test_written_out_basis_rotation_equals_mitsubas():
    """stokes.rotated_facet_mueller (the facet Mueller matrix rotated entry by entry, issue 26) equals
    Mitsuba's rotate_mueller_basis of the same matrix: 2000 random direction pairs and entries,
    spectral polarized, every entry to 2e-6 absolute (float32 rounding of O(1) entries); lanes
    outside the mask are exactly 0."""
    import drjit as dr
    import mitsuba as mi

    from hyde_bsdf.mitsuba import optics as po
    from hyde_bsdf.mitsuba import stokes as ps

    set_variant("llvm_ad_spectral_polarized")
    rng = np.random.default_rng(26)
    n = 2000

    def unit():
        v = rng.normal(size=(3, n))
        return dr.normalize(mi.Vector3f(*(mi.Float(x.astype(np.float32)) for x in v)))

    def spectrum():
        return mi.UnpolarizedSpectrum(*(mi.Float(rng.uniform(-1, 1, n).astype(np.float32)) for _ in range(4)))

    wo_hat, wi_hat = unit(), unit()
    a, b, c, s = spectrum(), spectrum(), spectrum(), spectrum()
    spec = mi.Float(rng.uniform(0, 2, n).astype(np.float32))
    F = dr.zeros(mi.Spectrum, n)
    F[0, 0], F[0, 1], F[1, 0], F[1, 1] = a * spec, b * spec, b * spec, a * spec
    F[2, 2], F[2, 3], F[3, 2], F[3, 3] = c * spec, -s * spec, s * spec, c * spec
    basis_in, basis_out = mi.mueller.stokes_basis(-wo_hat), mi.mueller.stokes_basis(wi_hat)
    s_axis = po.safe_normalize(po.accurate_cross(wo_hat, wi_hat), basis_in)
    ref = mi.mueller.rotate_mueller_basis(F, -wo_hat, s_axis, basis_in, wi_hat, s_axis, basis_out)
    mask = dr.arange(mi.UInt32, n) % 7 != 0
    rot_in = [dr.select(mask, x, 0.0) for x in ps.stokes_rotation(-wo_hat, s_axis, basis_in)]
    rot_out = [dr.select(mask, x, 0.0) for x in ps.stokes_rotation(wi_hat, s_axis, basis_out)]
    got = ps.rotated_facet_mueller(a, b, c, s, rot_in, rot_out, dr.select(mask, spec, 0.0), 0.0)
    keep = np.array(mask)
    for i in range(4):
        for j in range(4):
            r = np.array(ref[i, j]).reshape(4, n)
            g = np.array(got[i, j]).reshape(4, n)
            assert np.abs(g[:, keep] - r[:, keep]).max() < 2e-6, (i, j)
            assert not g[:, ~keep].any(), (i, j)


def test_update_of_eta_alone_is_checked_against_the_current_k():
    """parameters_changed checks only the changed parameters and reuses the values of the one that
    did not change (issue 26): eta -> 0 with k = 0 is still refused (no material has index 0),
    after k moved to 2 it is accepted, and k -> 0 then is refused again; a refusal restores."""
    import mitsuba as mi
    import pytest

    set_variant("llvm_ad_rgb")
    hyde_bsdf.register()
    b = mi.load_dict({"type": "hyde", "alpha": 0.3, "eta": 1.5, "k": 0.0})
    p = mi.traverse(b)
    p["eta.value"] = 0.0
    with pytest.raises(ValueError, match="cannot both be 0"):
        p.update()
    assert np.array(mi.traverse(b)["eta.value"]).ravel()[0] == 1.5
    p = mi.traverse(b)
    p["k.value"] = 2.0
    p.update()
    p["eta.value"] = 0.0
    p.update()
    p["k.value"] = 0.0
    with pytest.raises(ValueError, match="cannot both be 0"):
        p.update()
    assert np.array(mi.traverse(b)["k.value"]).ravel()[0] == 2.0
