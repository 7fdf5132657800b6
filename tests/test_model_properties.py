"""Property tests of the NumPy model's public functions over their whole input space (issue 10).

Checked with Hypothesis, edges included (theta 0, 90 deg, 180 deg and beyond; rms_slope 1e-4
and 100 and outside; k from 0 to 1e6 and beyond; any phi, NaN and infinity): ``pbrdf`` and
``dhr_specular_pec`` either return finite numbers -- with F_00 >= 0 and rho in [0, 1] where the
model bounds it -- or raise ValueError/TypeError, exactly when an argument is outside its
documented range; they never return NaN, never raise anything else and never leak a NumPy
RuntimeWarning.  A table of bad arguments checks that each refusal names the parameter.
"""
import math
import warnings

import numpy as np
import pytest
from hypothesis import HealthCheck, example, given, settings, strategies as st
from conftest import examples

import hyde_bsdf
from hyde_bsdf.model import dhr
from hyde_bsdf.model.parameters import DHR_TABLE_RMS_SLOPE, INDEX_MIN, N, RMS_SLOPE
from hyde_bsdf.model.terms import DIFFUSE, SHADOWING, allowed

INDEX_MAX = N.hi
RMS_SLOPE_RANGE = RMS_SLOPE.bounds

HALF_PI = 0.5 * math.pi
EDGE_ANGLES = [0.0, 1e-300, 1e-12, HALF_PI - 1e-12, HALF_PI, HALF_PI + 1e-12, math.pi, math.pi + 1e-9,
               -1e-300, -0.1, 4.0, float("nan"), float("inf")]
polar = st.one_of(st.sampled_from(EDGE_ANGLES), st.floats(-0.5, 3.5))
azimuth = st.one_of(st.sampled_from([0.0, math.pi, -math.pi, 2 * math.pi, 1e300, -1e300,
                                     float("nan"), float("-inf")]),
                    st.floats(-1e6, 1e6, allow_nan=False))
slope = st.one_of(st.sampled_from([1e-4, 50.0, 50.0 * (1 + 1e-9), 100.0, 1e-4 * (1 - 1e-9), 100.0 * (1 + 1e-9), 0.0, -0.3, 1e-300,
                                   1e300, float("nan"), float("inf")]),
                  st.floats(1e-4, 100.0), st.floats(1e-6, 1e3))
index = st.one_of(st.sampled_from([0.0, 1e-7, 1e-6, 1.0, INDEX_MAX, INDEX_MAX * (1 + 1e-9), -1e-9, 1e7,
                                   float("nan"), float("inf")]),
                  st.floats(0.0, 1e6), st.floats(0.0, 20.0))
PROFILE = settings(max_examples=examples(250), deadline=None, suppress_health_check=[HealthCheck.too_slow])


def pbrdf_accepts(ti, tr, ph, s, n, k, pec, shadowing, diffuse):
    """The documented domain of pbrdf (its docstring and the evaluator's ranges)."""
    finite = all(math.isfinite(v) for v in (ti, tr, ph))
    angles = finite and 0.0 <= ti <= math.pi and 0.0 <= tr <= math.pi
    slope_ok = math.isfinite(s) and RMS_SLOPE_RANGE[0] <= s <= RMS_SLOPE_RANGE[1]
    index_ok = pec or (all(math.isfinite(v) and 0.0 <= v <= INDEX_MAX for v in (n, k))
                       and math.hypot(n, k) >= INDEX_MIN)
    combo_ok = allowed(shadowing, diffuse)     # the terms' rule (model/terms.py)
    return angles and slope_ok and index_ok and combo_ok


@PROFILE
@given(ti=polar, tr=polar, ph=azimuth, s=slope, n=index, k=index, pec=st.booleans(),
       shadowing=st.sampled_from(SHADOWING), diffuse=st.sampled_from(DIFFUSE))
@example(ti=HALF_PI, tr=HALF_PI, ph=math.pi, s=1e-4, n=0.0, k=1e6, pec=False, shadowing="vgroove",
         diffuse="paper")
@example(ti=0.0, tr=0.0, ph=0.0, s=100.0, n=1e6, k=0.0, pec=False, shadowing="smith", diffuse="reciprocal")
@example(ti=1.5707963, tr=1.5707963, ph=math.pi, s=1e-4, n=0.0, k=0.0, pec=True, shadowing="none",
         diffuse="paper")
def test_pbrdf_is_finite_or_refuses(ti, tr, ph, s, n, k, pec, shadowing, diffuse):
    kw = dict(pec=True) if pec else dict(n=n, k=k)
    accepted = pbrdf_accepts(ti, tr, ph, s, n, k, pec, shadowing, diffuse)
    with warnings.catch_warnings():
        warnings.simplefilter("error", RuntimeWarning)      # no overflow/invalid leaks either
        try:
            F = hyde_bsdf.pbrdf(ti, tr, ph, rms_slope=s, shadowing=shadowing, diffuse=diffuse, **kw)
        except ValueError:
            assert not accepted, "refused an input inside the documented domain"
            return
    assert accepted, "accepted an input outside the documented domain"
    assert F.shape == (4, 4) and np.all(np.isfinite(F))
    assert F[0, 0] >= 0.0
    if math.cos(ti) <= 0.0 or math.cos(tr) <= 0.0:
        assert np.all(F == 0.0)                            # at or below the horizon
    # the specular Mueller matrix of a facet is physical: |F_ij| <= F_00 (diffuse adds to F_00)
    assert np.all(np.abs(F) <= F[0, 0] * (1 + 1e-9) + 1e-300)


@PROFILE
@given(ti=st.lists(polar, min_size=1, max_size=6), s=slope)
def test_pbrdf_arrays_are_finite_or_refused(ti, s):
    """Arrays with one bad entry are refused as a whole; valid arrays give finite arrays."""
    t = np.array(ti)
    ok = np.all(np.isfinite(t)) and np.all((t >= 0) & (t <= math.pi)) and math.isfinite(s) \
        and RMS_SLOPE_RANGE[0] <= s <= RMS_SLOPE_RANGE[1]
    try:
        F = hyde_bsdf.pbrdf(t, t[::-1], math.pi, rms_slope=s, n=0.285, k=7.3523)
    except ValueError:
        assert not ok
        return
    assert ok and F.shape == (t.size, 4, 4) and np.all(np.isfinite(F))


@PROFILE
@given(ti=polar, s=slope, shadowing=st.sampled_from(["vgroove", "smith", "none"]))
@example(ti=HALF_PI, s=1e-4, shadowing="vgroove")
@example(ti=HALF_PI, s=100.0, shadowing="smith")
@example(ti=0.0, s=100.0, shadowing="none")
@example(ti=2.225073858507203e-309, s=1e-4, shadowing="vgroove")      # found by Hypothesis: overflow warning
def test_dhr_specular_pec_is_finite_or_refuses(ti, s, shadowing):
    accepted = (math.isfinite(ti) and 0.0 <= ti <= HALF_PI and math.isfinite(s)
                and DHR_TABLE_RMS_SLOPE[0] <= s <= DHR_TABLE_RMS_SLOPE[1] * (1 + 1e-12))
    with warnings.catch_warnings():
        warnings.simplefilter("error", RuntimeWarning)
        try:
            rho = dhr.dhr_specular_pec(ti, s, shadowing)
        except ValueError:
            assert not accepted
            return
    assert accepted
    assert np.isfinite(rho) and rho >= 0.0
    if shadowing != "none":          # shadowing bounds the single-scattering DHR by 1 (Eq. 15)
        assert rho <= 1.0 + 1e-9


# ---------------------------------------------------------------------------- bad arguments

def call_pbrdf(**over):
    args = dict(theta_i=0.3, theta_r=0.4, phi=1.0, rms_slope=0.3, n=1.5, k=0.0)
    args.update(over)
    return hyde_bsdf.pbrdf(args.pop("theta_i"), args.pop("theta_r"), args.pop("phi"), **args)


def call_dhr(**over):
    args = dict(theta_i=0.3, rms_slope=0.3)
    args.update(over)
    return hyde_bsdf.dhr_specular_pec(args.pop("theta_i"), args.pop("rms_slope"), **args)


BAD = [
    # (function, bad argument, exception, text the message must contain)
    (call_pbrdf, dict(theta_i=0.3 + 0.1j), TypeError, "theta_i"),
    (call_pbrdf, dict(theta_r=np.array([0.3, 0.4 + 1j])), TypeError, "theta_r"),
    (call_pbrdf, dict(phi="1.0"), TypeError, "phi"),
    (call_pbrdf, dict(theta_i=True), TypeError, "theta_i"),
    (call_pbrdf, dict(theta_i=[0.1, None]), TypeError, "theta_i"),
    (call_pbrdf, dict(theta_i=[[0.1, 0.2], [0.3]]), ValueError, "theta_i"),
    (call_pbrdf, dict(theta_i=np.zeros(3), theta_r=np.zeros(4)), ValueError, "theta_r (4,)"),
    (call_pbrdf, dict(phi=np.zeros((2, 3)), theta_i=np.zeros(2)), ValueError, "phi (2, 3)"),
    (call_pbrdf, dict(theta_i=float("nan")), ValueError, "theta_i"),
    (call_pbrdf, dict(theta_r=3.5), ValueError, "theta_r"),
    (call_pbrdf, dict(rms_slope=0.3 + 0j), TypeError, "rms_slope"),
    (call_pbrdf, dict(rms_slope=np.complex128(0.3)), TypeError, "rms_slope"),
    (call_pbrdf, dict(rms_slope="0.3"), TypeError, "rms_slope"),
    (call_pbrdf, dict(rms_slope=np.array([0.3, 0.4])), TypeError, "rms_slope"),
    (call_pbrdf, dict(rms_slope=200.0), ValueError, "rms_slope must be a finite number in [0.0001, 50]"),
    (call_pbrdf, dict(n=1.5 - 7j), TypeError, "n must be a real number"),
    (call_pbrdf, dict(k="7"), TypeError, "k must be a real number"),
    (call_pbrdf, dict(k=np.array([1.0, 2.0])), TypeError, "k must be a real number"),
    (call_pbrdf, dict(k=2e6), ValueError, "k must be a finite number in [0, 1e+06]"),
    (call_pbrdf, dict(n=None, k=0.0, pec="no"), TypeError, "pec must be True or False"),
    (call_pbrdf, dict(n=None, k=0.0, pec=1), TypeError, "pec must be True or False"),
    (call_pbrdf, dict(shadowing=None), ValueError, "shadowing must be one of"),
    (call_dhr, dict(theta_i=0.3 + 0.1j), TypeError, "theta_i"),
    (call_dhr, dict(theta_i="0.3"), TypeError, "theta_i"),
    (call_dhr, dict(rms_slope=[0.3j]), TypeError, "rms_slope"),
    (call_dhr, dict(theta_i=np.zeros(3), rms_slope=np.full(2, 0.3)), ValueError, "rms_slope (2,)"),
    (call_dhr, dict(theta_i=2.0), ValueError, "theta_i must be in [0, pi/2]"),
    (call_dhr, dict(rms_slope=1e-30), ValueError, "rms_slope must be in [0.0001, 100]"),
    (call_dhr, dict(rms_slope=float("inf")), ValueError, "rms_slope"),
    (call_dhr, dict(shadowing=3), ValueError, "shadowing"),
    (call_dhr, dict(error_estimate="yes"), TypeError, "error_estimate"),
]


@pytest.mark.parametrize("call, bad, exc, text", BAD,
                         ids=[f"{c.__name__[5:]}-{next(iter(b))}-{i}" for i, (c, b, _, _) in enumerate(BAD)])
def test_bad_arguments_are_refused_naming_the_parameter(call, bad, exc, text):
    with pytest.raises(exc) as info:
        call(**bad)
    assert text in str(info.value), str(info.value)
    assert "\n" not in str(info.value)


def test_non_finite_result_message_names_the_index(monkeypatch):
    """The guard against NaN output names where it happened (it said 'index []' before)."""
    from hyde_bsdf.model import evaluator

    real = evaluator.rotated_fresnel_mueller

    def poisoned(*args):                        # one block of 6 directions: element (0, 3) of the 6th, [1, 2]
        real(*args)
        args[-1][0, 3, 5] = np.nan

    monkeypatch.setattr(evaluator, "rotated_fresnel_mueller", poisoned)
    with pytest.raises(FloatingPointError, match=r"index \[1, 2\]"):
        hyde_bsdf.pbrdf(np.full((2, 3), 0.3), 0.4, 1.0, rms_slope=0.3, pec=True)


TINY = st.floats(-38.0, -3.0).map(lambda e: 10.0 ** e)
#: (theta_i, theta_r, phi) of nearly collinear directions, eps from the normal or from each other
NEAR = {
    "wi normal, wo near it": lambda e, a: (0.0, e, a),
    "wo normal, wi near it": lambda e, a: (e, 0.0, a),
    "both near the normal": lambda e, a: (e, 2 * e, a),
    "backscatter + eps": lambda e, a: (0.7, 0.7 + e * math.cos(a), e * math.sin(a)),
    "mirror + eps": lambda e, a: (0.7, 0.7 + e * math.cos(a), math.pi + e * math.sin(a)),
    "grazing, opposite + eps": lambda e, a: (HALF_PI - e, HALF_PI - e, math.pi),
}


@settings(max_examples=examples(150), deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(eps=TINY, az=st.floats(0.0, 2 * math.pi), case=st.sampled_from(sorted(NEAR)),
       s=st.sampled_from([1e-4, 0.3, 50.0]), shadowing=st.sampled_from(["vgroove", "smith", "none"]),
       metal=st.booleans())
@example(eps=1e-30, az=0.0, case="wi normal, wo near it", s=0.3, shadowing="vgroove", metal=True)  # issue 15
def test_pbrdf_near_collinear_directions_are_finite_and_continuous(eps, az, case, s, shadowing, metal):
    """Directions within 1e-38 ... 1e-3 of the normal and of each other (issue 15): finite, and
    within eps <= 1e-6 of the normal equal to the value at exact normal incidence (1e-5 relative)."""
    ti, tr, ph = NEAR[case](eps, az)
    kw = dict(n=0.2, k=3.0) if metal else dict(n=1.5, k=0.0)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        m = np.asarray(hyde_bsdf.pbrdf(ti, tr, ph, rms_slope=s, shadowing=shadowing, **kw))
    assert np.isfinite(m).all()
    if case.startswith(("wi normal", "wo normal")) and eps <= 1e-6 and s == 0.3:
        ref = np.asarray(hyde_bsdf.pbrdf(0.0, 0.0, ph, rms_slope=s, shadowing=shadowing, **kw))
        # the s/p bases at theta = 0 are the limit at fixed azimuth: compare M00 and the
        # rotation invariants of the linear block, which do not depend on that choice
        m, ref = m.reshape(4, 4), ref.reshape(4, 4)
        assert abs(m[0, 0] - ref[0, 0]) <= 1e-5 * abs(ref[0, 0])
        assert abs(np.linalg.norm(m[1:3, 1:3]) - np.linalg.norm(ref[1:3, 1:3])) <= 1e-5 * abs(ref[0, 0])
