"""Any index Mitsuba accepts for a conductor: a dispersive dielectric (spectrum eta, k = 0) gives
the Fresnel reflectance of glass; only an index that really is 0 is refused; the
``sample_visible`` switch given as a string is parsed, not taken as truthy."""
import math

import numpy as np
import pytest

from conftest import mitsuba_with_hyde

GLASS = '<spectrum name="eta" value="400:1.53, 700:1.51"/><float name="k" value="0"/>'



def _xml(mi, body):
    return mi.load_string(f'<bsdf version="3.0.0" type="hyde">{body}</bsdf>')


def _eta_glass(wl):
    return 1.53 + (wl - 400.0) / 300.0 * (1.51 - 1.53)


@pytest.mark.parametrize("variant", ["scalar_spectral_polarized", "llvm_ad_spectral_polarized"])
def test_dielectric_spectrum_gives_the_fresnel_reflectance_of_glass(variant):
    """At normal incidence (wi = wo = +z, specular lobe only) eval = D(z) G F / 4 with
    D(z) = 1 / (pi alpha^2) and G = 1, so F = 4 pi alpha^2 eval = ((n - 1)/(n + 1))^2, and the
    Mueller matrix is F diag(1, 1, -1, -1) in Mitsuba's bases, per wavelength."""
    import drjit as dr

    mi = mitsuba_with_hyde(variant)
    rms = 0.2
    with pytest.warns(RuntimeWarning, match="eta and k are both 0 at 360-390 nm, 710-830 nm"):
        b = _xml(mi, f'<float name="rms_slope" value="{rms}"/>{GLASS}<string name="diffuse" value="none"/>')
    wls = [420.0, 500.0, 600.0, 690.0]
    si = dr.zeros(mi.SurfaceInteraction3f)
    si.wi = mi.Vector3f(0, 0, 1)
    si.wavelengths = mi.UnpolarizedSpectrum(*wls)
    v = b.eval(mi.BSDFContext(), si, mi.Vector3f(0, 0, 1))
    m = np.array([[np.asarray(v[r, c], dtype=float).ravel() for c in range(4)] for r in range(4)])  # [4, 4, wl]
    alpha2 = 2 * rms * rms
    F = 4 * math.pi * alpha2 * m[0, 0]
    n = _eta_glass(np.array(wls))
    want = ((n - 1) / (n + 1)) ** 2
    assert np.allclose(F, want, rtol=2e-5, atol=0), (F, want)
    for j in range(4):
        assert np.allclose(m[:, :, j] / m[0, 0, j], np.diag([1.0, 1.0, -1.0, -1.0]), atol=1e-6)


def test_dielectric_spectrum_equals_roughconductor_with_the_same_index():
    """hyde (smith, no diffuse) and roughconductor with eta = the glass spectrum, k = 0."""
    import drjit as dr

    mi = mitsuba_with_hyde("llvm_ad_spectral_polarized")
    with pytest.warns(RuntimeWarning):
        hyde = _xml(mi, f'<float name="alpha" value="0.3"/>{GLASS}<string name="shadowing" value="smith"/>'
                        f'<string name="diffuse" value="none"/>')
    rc = mi.load_string(f'<bsdf version="3.0.0" type="roughconductor"><string name="distribution" '
                        f'value="beckmann"/><float name="alpha" value="0.3"/>{GLASS}</bsdf>')
    rng = np.random.default_rng(2)
    n = 2000

    def hemi():
        z = rng.uniform(0.1, 1, n)
        ph = rng.uniform(0, 2 * np.pi, n)
        r = np.sqrt(1 - z * z)
        return mi.Vector3f(*(mi.Float(a.astype(np.float32)) for a in (r * np.cos(ph), r * np.sin(ph), z)))

    si = dr.zeros(mi.SurfaceInteraction3f, n)
    si.wi = hemi()
    si.wavelengths = mi.UnpolarizedSpectrum(450.0, 550.0, 650.0, 690.0)
    wo = hemi()
    a = hyde.eval(mi.BSDFContext(), si, wo)
    b = rc.eval(mi.BSDFContext(), si, wo)
    A = np.array([[np.asarray(a[r, c]) for c in range(4)] for r in range(4)])
    B = np.array([[np.asarray(b[r, c]) for c in range(4)] for r in range(4)])
    scale = np.abs(B).max(axis=(0, 1), keepdims=True) + 1e-7
    assert B[0, 0].max() > 0.05
    assert (np.abs(A - B) / scale).max() <= 5e-5


def test_only_an_index_that_really_is_zero_is_refused():
    mi = mitsuba_with_hyde("scalar_spectral_polarized")
    zero = '<spectrum name="eta" value="400:0, 700:0"/><float name="k" value="0"/>'
    with pytest.raises(Exception, match="hyde: parameter 'eta'.*eta and k both 0"):
        _xml(mi, zero)
    _xml(mi, '<spectrum name="eta" value="300:1.5, 900:1.5"/><float name="k" value="0"/>')  # no warning
    _xml(mi, '<rgb name="eta" value="1.5, 1.5, 1.5"/><float name="k" value="0"/>')
    rgb = mitsuba_with_hyde("llvm_ad_rgb")
    rgb.load_string('<bsdf version="3.0.0" type="hyde"><rgb name="eta" value="1.5, 1.4, 1.3"/>'
                    '<float name="k" value="0"/></bsdf>')
    with pytest.raises(Exception, match="eta and k cannot both be 0"):
        rgb.load_string('<bsdf version="3.0.0" type="hyde"><rgb name="eta" value="0, 0, 0"/>'
                        '<float name="k" value="0"/></bsdf>')


def test_sample_visible_string_is_parsed():
    mi = mitsuba_with_hyde("scalar_rgb")
    for text, want in (("false", False), ("False", False), ("true", True)):
        b = _xml(mi, f'<string name="sample_visible" value="{text}"/>')
        assert b.m_sample_visible is want
        assert mi.load_dict({"type": "hyde", "sample_visible": text}).m_sample_visible is want
    assert _xml(mi, '<boolean name="sample_visible" value="false"/>').m_sample_visible is False
    with pytest.raises(Exception, match="sample_visible.*boolean"):
        _xml(mi, '<string name="sample_visible" value="no"/>')
