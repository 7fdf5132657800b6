"""The mappings to SCATMECH and Mitsuba (issue 30 item 6; docs/conventions.md, hyde_bsdf.model.conventions).

Physics checked, against the evaluator: with phi_hyde = pi + phi_SCATMECH the in-plane specular peak
of M00 lies at phi_SCATMECH = 0; the S3 map Q F Q flips exactly the S3 row and column (M33 and the
12 other elements unchanged) and is its own inverse, so a SCATMECH matrix maps back to pbrdf's; a
Gaussian facet-slope density with SCATMECH's slope parameter sqrt(2) rms_slope is the evaluator's
Beckmann D; Mitsuba's Beckmann distribution at alpha = sqrt(2) rms_slope is the evaluator's D (float32).
(SCATMECH itself is not installed here: the comparison to it, 1.6e-13 under these maps, is the
record in docs/conventions.md.)  Under 1 s.
"""
import math

import numpy as np
import pytest

from hyde_bsdf import pbrdf
from hyde_bsdf.model import conventions as cv
from hyde_bsdf.model.slope_distribution import beckmann_D


def test_the_specular_peak_is_phi_scatmech_zero():
    phi_s = np.radians(np.linspace(-180, 180, 721))
    F = pbrdf(0.6, 0.6, cv.phi_from_scatmech(phi_s), rms_slope=0.1, n=1.5, k=3.0, diffuse="none")
    assert abs(phi_s[np.argmax(F[:, 0, 0])]) < 1e-12
    assert cv.phi_to_scatmech(math.pi) == 0.0


def test_the_s3_map_flips_the_s3_row_and_column_only():
    F = pbrdf(0.5, 0.8, 2.1, rms_slope=0.3, n=0.2, k=3.4)          # out of plane: every element nonzero
    S = cv.mueller_to_scatmech(F)
    sign = np.ones((4, 4))
    sign[3, :3] = sign[:3, 3] = -1.0
    np.testing.assert_array_equal(S, sign * F)
    np.testing.assert_array_equal(cv.mueller_from_scatmech(S), F)


def test_scatmech_slope_is_beckmann_alpha_of_the_evaluators_distribution():
    """A Gaussian slope density with SCATMECH's parameter s: exp(-tan^2 / s^2) / (pi s^2 cos^4) = beckmann_D."""
    rms = 0.27
    s = cv.scatmech_slope(rms)
    theta = np.radians(np.linspace(0, 80, 50))
    c = np.cos(theta)
    gaussian = np.exp(-np.tan(theta) ** 2 / s ** 2) / (math.pi * s ** 2 * c ** 4)
    np.testing.assert_allclose(gaussian, beckmann_D(c, np.tan(theta) ** 2, rms), rtol=1e-13)
    assert cv.rms_slope_from_scatmech(s) == pytest.approx(rms, rel=1e-15)


def test_mitsuba_beckmann_alpha_is_sqrt2_rms_slope():
    mi = pytest.importorskip("mitsuba")
    from hyde_bsdf.mitsuba.variants import set_variant
    from hyde_bsdf.model.parameters import alpha_from_rms_slope

    set_variant("scalar_rgb", fallback=False)
    rms = 0.27
    distr = mi.MicrofacetDistribution(mi.MicrofacetType.Beckmann, alpha_from_rms_slope(rms), True)
    for deg in (0.0, 20.0, 50.0):
        t = math.radians(deg)
        h = mi.Vector3f(math.sin(t), 0.0, math.cos(t))
        want = beckmann_D(math.cos(t), math.tan(t) ** 2, rms)
        assert float(distr.eval(h)) == pytest.approx(want, rel=2e-6)
