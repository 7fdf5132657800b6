"""The plugin's Lambertian term (issue 30): ``diffuse="lambertian"`` with its own albedo
``diffuse_reflectance``, textured and differentiable like the other parameters.

Physics checked: the term adds diffuse_reflectance cos(theta_o) / pi to the unpolarized [0, 0]
element only (a depolarizer: the other 15 elements are the specular lobe's); the derivative of
eval with respect to the albedo is cos(theta_o) / pi (automatic differentiation against the
analytic value); a bitmap albedo is read per shading point; an albedo outside [0, 1] or given to
another diffuse term is refused with one line.  (Against the evaluator: tests/test_plugin_evaluator.py;
sampling: tests/test_plugin_sampling.py.)  About 3 s.
"""
import math

import numpy as np
import pytest

from conftest import mitsuba_with_hyde



def _query(mi, theta_i=0.5, theta_o=0.9, phi=0.4, uv=(0.5, 0.5)):
    import drjit as dr

    si = dr.zeros(mi.SurfaceInteraction3f)
    si.wi = mi.Vector3f(math.sin(theta_i), 0.0, math.cos(theta_i))
    si.uv = mi.Point2f(*uv)
    if mi.is_spectral:
        si.wavelengths = mi.UnpolarizedSpectrum(550.0)
    wo = mi.Vector3f(-math.sin(theta_o) * math.cos(phi), -math.sin(theta_o) * math.sin(phi), math.cos(theta_o))
    return si, wo


def _bsdf(mi, **extra):
    return mi.load_dict({"type": "hyde", "rms_slope": 0.3, "eta": 1.5, "k": 3.0, "shadowing": "smith", **extra})


def test_the_albedo_adds_to_the_unpolarized_element_only():
    mi = mitsuba_with_hyde("llvm_ad_spectral_polarized")
    si, wo = _query(mi)
    with_term = np.array(_bsdf(mi, diffuse="lambertian", diffuse_reflectance=0.2).eval(mi.BSDFContext(), si, wo))
    without = np.array(_bsdf(mi, diffuse="none").eval(mi.BSDFContext(), si, wo))
    diff = (with_term - without).reshape(4, 4, -1)[..., 0]
    assert diff[0, 0] == pytest.approx(0.2 * math.cos(0.9) / math.pi, rel=1e-6)
    assert np.abs(diff.ravel()[1:]).max() < 1e-7


def test_the_albedo_is_differentiable():
    """d eval / d diffuse_reflectance = cos(theta_o) / pi (rgb variant, every channel)."""
    import drjit as dr
    mi = mitsuba_with_hyde("llvm_ad_rgb")
    bsdf = _bsdf(mi, diffuse="lambertian", diffuse_reflectance=0.2)
    params = mi.traverse(bsdf)
    assert "diffuse_reflectance.value" in params.keys()
    assert not params.flags("diffuse_reflectance.value") & mi.ParamFlags.NonDifferentiable
    dr.enable_grad(params["diffuse_reflectance.value"])
    params.update()
    si, wo = _query(mi)
    value = bsdf.eval(mi.BSDFContext(), si, wo)
    dr.backward(dr.sum(value[0]))
    assert float(dr.grad(params["diffuse_reflectance.value"])[0]) == pytest.approx(math.cos(0.9) / math.pi, rel=1e-5)


def test_a_bitmap_albedo_is_read_per_shading_point(tmp_path):
    mi = mitsuba_with_hyde("llvm_ad_rgb")
    data = np.array([[[0.1], [0.4]]], np.float32)          # 1 x 2 texels: 0.1 on the left, 0.4 on the right
    tex = {"type": "bitmap", "bitmap": mi.Bitmap(data), "filter_type": "nearest", "raw": True}
    lam, base = _bsdf(mi, diffuse="lambertian", diffuse_reflectance=tex), _bsdf(mi, diffuse="none")
    for u, albedo in ((0.25, 0.1), (0.75, 0.4)):
        si, wo = _query(mi, uv=(u, 0.5))
        d = np.array(lam.eval(mi.BSDFContext(), si, wo))[0] - np.array(base.eval(mi.BSDFContext(), si, wo))[0]
        assert float(np.ravel(d)[0]) == pytest.approx(albedo * math.cos(0.9) / math.pi, rel=1e-5)


@pytest.mark.parametrize("extra, match", [
    (dict(diffuse="lambertian", diffuse_reflectance=1.2), r"'diffuse_reflectance' must be finite and in \[0, 1\]"),
    (dict(diffuse="paper", diffuse_reflectance=0.2), r"diffuse_reflectance is the albedo of diffuse='lambertian'"),
])
def test_a_wrong_albedo_is_refused_in_one_line(extra, match):
    mi = mitsuba_with_hyde("llvm_ad_rgb")
    with pytest.raises(Exception, match=match) as info:      # Mitsuba's load_dict re-raises as RuntimeError
        _bsdf(mi, **extra)
    assert str(info.value).strip().splitlines()[-1].startswith("UsageError: hyde:")
