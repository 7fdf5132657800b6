"""Chi-square test of the ``hyde`` plugin's sampling (``mitsuba.chi2``), polarized variants included.

Mitsuba's stock ``BSDFAdapter`` tests ``dr.all(weight == 0)`` on the sample
weight, which is wrong for the 4x4 Mueller weights of polarized variants.  This
adapter reduces the weight to its unpolarized part (``mi.unpolarized_spectrum``,
the [0, 0] element) first, and builds the BSDF once instead of per call.

It tests that the density of the directions ``sample`` draws matches ``pdf``
(the histogram against the integrated pdf, Mitsuba's standard chi^2 test on
``SphericalDomain``).  A sample counts when it is valid: a non-zero weight, or
a direction above the surface with ``bs.pdf > 0``.  (Mitsuba's adapter drops
every zero-weight sample; a mixture sampler legitimately draws directions where
one lobe's density is positive but the BSDF value is 0 - e.g. a diffuse-lobe
sample on a surface so smooth that 1 - rho = 0 - and dropping those would
compare the histogram with the wrong density.)
"""
from __future__ import annotations

import math

import drjit as dr
import mitsuba as mi

__all__ = ["bsdf_adapter", "chi2_test"]


def bsdf_adapter(bsdf, wi, ctx=None, wavelength=550.0):
    """(sample_func, pdf_func) for ``mi.chi2.ChiSquareTest`` at incident direction ``wi``."""
    if ctx is None:
        ctx = mi.BSDFContext()

    def make_si(n):
        si = dr.zeros(mi.SurfaceInteraction3f, n)
        si.wi = mi.Vector3f(wi)
        if mi.is_spectral:
            si.wavelengths = mi.UnpolarizedSpectrum(wavelength)
        return si

    def sample_functor(sample, *args):
        n = dr.width(sample)
        bs, weight = bsdf.sample(ctx, make_si(n), sample[0], mi.Point2f(sample[1], sample[2]))
        w_unpol = mi.unpolarized_spectrum(weight) if mi.is_polarized else weight
        valid = ~dr.all(w_unpol == 0) | (bs.pdf > 0)
        # the harness bins -cos(theta) in float32: 0 < cos < ~1e-7 lands in the cell *below*
        # the horizon (pdf 0 there), so such razor-grazing samples (a 1e-6 sliver of the
        # first cell) are left out rather than reported as "samples where pdf = 0"
        valid &= mi.Frame3f.cos_theta(bs.wo) > 1e-6
        w = dr.select(valid, 1.0, 0.0)
        return bs.wo, mi.Float(w)

    def pdf_functor(wo, *args):
        return bsdf.pdf(ctx, make_si(dr.width(wo)), wo)

    return sample_functor, pdf_functor


def chi2_test(bsdf, theta_i, *, sample_count=200_000, res=48, ires=4, seed=0,
              significance_level=0.01, test_count=1):
    """Run Mitsuba's chi^2 test for ``bsdf`` lit from polar angle ``theta_i`` (radians).

    Returns ``(passed, p_value, messages)``.  ``test_count`` applies Sidak's
    correction when several tests are run at the same significance level.
    """
    from mitsuba.chi2 import ChiSquareTest, SphericalDomain

    wi = [math.sin(theta_i), 0.0, math.cos(theta_i)]
    sample_func, pdf_func = bsdf_adapter(bsdf, wi)
    test = ChiSquareTest(domain=SphericalDomain(), sample_func=sample_func, pdf_func=pdf_func,
                         sample_dim=3, sample_count=sample_count, res=res, ires=ires, seed=seed)
    passed = test.run(significance_level=significance_level, test_count=test_count, quiet=True)
    return bool(passed), test.p_value, test.messages
