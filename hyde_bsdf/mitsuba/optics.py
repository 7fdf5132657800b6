"""Dr.Jit building blocks of the ``hyde`` Mitsuba BSDF (vector form of paper Eqs. 9-17).

These functions are written with Dr.Jit operations only, so they run unchanged
in every Mitsuba variant (scalar, LLVM, CUDA; RGB, spectral, mono) and carry
gradients in the ``*_ad_*`` variants.  They are a derivation independent of the
NumPy evaluator (:mod:`hyde_bsdf.model.evaluator`), which uses the paper's angle
formulas; the two only share data: the DHR table (:mod:`hyde_bsdf.model.dhr`) and the
parameter ranges (:mod:`hyde_bsdf.model.parameters`).

Conventions used here
---------------------
* Vectors are in the local shading frame, the mean surface normal is +z.
* The complex index is given as ``n``, ``k`` >= 0 and used as eta = n - i k,
  the sign that Mitsuba's polarized Fresnel code (``fresnel_polarized``) and the
  paper (eta = n - j kappa) use; Mitsuba's user-facing ``eta + i k`` describes
  the same material.  Amplitude signs follow Mitsuba (r_p = -r_s at normal incidence).
* A facet Mueller matrix is expressed in the facet's own s/p bases: its Stokes
  reference axis is the facet's s direction (perpendicular to the facet plane
  of incidence), exactly as ``mi.mueller.specular_reflection`` returns it.
"""
from __future__ import annotations


import math

import drjit as dr
import mitsuba as mi
import numpy as np

__all__ = [
    "accurate_cross",
    "safe_normalize",
    "snap_to_normal",
    "MIN_NORM",
    "complex_sqrt_lower",
    "facet_fresnel",
    "fresnel_mueller_entries",
    "fresnel_average",
    "smith_g1_exact",
    "vgroove_g",
    "DHRLookup",
    "DHRSlice",
    "aligned_float32",
]


def aligned_float32(values) -> np.ndarray:
    """``values`` as a contiguous float32 NumPy array whose memory starts on a 64-byte boundary, for Dr.Jit.

    Dr.Jit's LLVM back end reads NumPy memory in place and writes the pointer's alignment into the kernel
    (``align 64`` or ``align 1``): arrays from NumPy's allocator (16-byte aligned) make another kernel whenever
    an address differs mod 64, one that neither the in-memory nor the on-disk kernel cache serves (measured:
    plugin_checks --quick compiled 75 kernels, 3.7 CPU s, that are 5 kernels up to the alignment).  The same
    values, so the same results."""
    a = np.asarray(values, dtype=np.float32)
    buf = np.empty(a.size + 16, dtype=np.float32)        # NumPy's blocks are 16-byte aligned: <= 12 floats off
    start = (-buf.ctypes.data % 64) // 4
    out = buf[start:start + a.size].reshape(a.shape)
    out[...] = a
    return out


# --------------------------------------------------------------------------
# small complex helpers on (re, im) pairs of Dr.Jit arrays
# --------------------------------------------------------------------------
def _cmul(ar, ai, br, bi):
    return ar * br - ai * bi, ar * bi + ai * br


def _cdiv(ar, ai, br, bi):
    # b is never 0 here: Re(b) >= cos(beta) > 0 or |b| >= |u| > 0 (see callers)
    inv = dr.rcp(br * br + bi * bi)
    return (ar * br + ai * bi) * inv, (ai * br - ar * bi) * inv


def _diff_of_products(a, b, c, d):
    """a b - c d with Kahan's compensation (one fma recovers the rounding error of c d)."""
    w = c * d
    err = dr.fma(-c, d, w)      # w - c d, exactly
    return dr.fma(a, b, -w) + err


def accurate_cross(u, v):
    """u x v, accurate even when u and v are nearly parallel.

    The facet's s axis is wo_hat x wi_hat; near backscatter (wi ~ wo) a plain
    float32 cross product loses ~eps / sin(angle) relative accuracy, which tilts
    the Stokes frames by ~1e-5 rad and shows up as 1e-5-level errors in the
    off-diagonal Mueller elements.  Kahan's difference of products avoids it.
    """
    return type(u)(_diff_of_products(u.y, v.z, u.z, v.y),
                   _diff_of_products(u.z, v.x, u.x, v.z),
                   _diff_of_products(u.x, v.y, u.y, v.x))


#: below this largest component a vector is taken as 0 by :func:`safe_normalize` (float32's
#: smallest normal number is 1.18e-38; LLVM may flush smaller ones to 0)
MIN_NORM = 1e-37


def safe_normalize(v, fallback):
    """``v / |v|``, or ``fallback`` (a unit vector) where ``v`` is (numerically) 0.

    The plain ``dr.normalize`` squares the components: in float32 a vector shorter than
    ~1e-19 underflows to a zero norm and gives Inf/NaN (for example the cross product of two
    directions 1e-30 apart, or the half vector of two opposite grazing directions).  Dividing
    by the largest component first keeps the squared norm in [1, 3], so the direction of any
    vector whose largest component is >= :data:`MIN_NORM` is exact; smaller ones are collinear
    to float32 precision and get the caller's named fallback.
    """
    m = dr.maximum(dr.maximum(dr.abs(v.x), dr.abs(v.y)), dr.abs(v.z))
    ok = m >= MIN_NORM
    u = v / dr.select(ok, m, 1.0)
    return dr.select(ok, dr.normalize(u), fallback)


def snap_to_normal(v):
    """``v`` with its x and y set to 0 where they are below 1e-15 |v.z| (a direction along the normal).

    Mitsuba's Beckmann ``smith_g1`` (and so ``G``, ``pdf`` and ``sample`` of
    ``mi.MicrofacetDistribution``) squares alpha v.x: for a direction within ~1e-19 of the
    normal that square is a float32 denormal and the rational approximation returns NaN
    (roughconductor shows it too).  For such directions tan(theta) alpha < 1e-13, where the
    exact G1 is 1 to float precision, and a direction exactly along the normal takes Mitsuba's
    own "perpendicular incidence" branch (G1 = 1): the snap changes no finite result.
    """
    x, y, z = v.x, v.y, v.z        # each component read once (a read creates a Python object: host cost)
    tiny = dr.maximum(dr.abs(x), dr.abs(y)) < 1e-15 * dr.abs(z)
    return type(v)(dr.select(tiny, 0.0, x), dr.select(tiny, 0.0, y), z)


def complex_sqrt_lower(zr, zi):
    """Square root of z = zr + i zi with Re >= 0 and Im <= 0 (z must have zi <= 0).

    The branch of the transmitted wave that decays into an absorbing medium with
    eta = n - i k (it equals Mitsuba's choice in ``fresnel_polarized``).  Uses the
    cancellation-free form (t1 from the larger of |z| +- zr, t2 = zi / (2 t1)).
    """
    mod = dr.sqrt(zr * zr + zi * zi)
    t1 = dr.sqrt(0.5 * (mod + dr.abs(zr)))
    # t1 == 0 only for z == 0 (dielectric at its critical angle); the root is then 0
    t1_pos, zr_pos = t1 > 0, zr >= 0        # each mask traced once (host cost per render)
    t2 = dr.select(t1_pos, 0.5 * dr.abs(zi) / dr.select(t1_pos, t1, 1.0), 0.0)
    re = dr.select(zr_pos, t1, t2)
    im = -dr.select(zr_pos, t2, t1)
    return re, im


def facet_fresnel(cos_beta, n, k):
    """Complex Fresnel amplitudes r_s, r_p of one facet (paper Eq. 9's r_s, r_p).

    Parameters
    ----------
    cos_beta : Float or UnpolarizedSpectrum, cosine of the facet incidence angle
        beta (cos beta = wi . h = wo . h), in [0, 1].
    n, k : UnpolarizedSpectrum, the index eta = n - i k (k >= 0).

    Returns
    -------
    (rs_re, rs_im, rp_re, rp_im) : the amplitudes in Mitsuba's sign convention
        (``fresnel_polarized``: r_p = -r_s = (eta - 1)/(eta + 1) at normal
        incidence, so a mirror's Mueller matrix there is diag(1, 1, -1, -1) as in
        the paper's bases), with r_s = (c - u)/(c + u), r_p = (eta^2 c - u)/(eta^2 c + u),
        u = eta cos(theta_t) = sqrt(eta^2 - sin^2 beta).
    """
    c = cos_beta
    sin2 = dr.maximum(1.0 - c * c, 0.0)  # rounding can push c slightly above 1
    e_re = n * n - k * k  # eta^2 = (n - ik)^2
    e_im = -2.0 * n * k
    u_re, u_im = complex_sqrt_lower(e_re - sin2, e_im)
    rs_re, rs_im = _cdiv(c - u_re, -u_im, c + u_re, u_im)
    ec_re, ec_im = e_re * c, e_im * c
    rp_re, rp_im = _cdiv(ec_re - u_re, ec_im - u_im, ec_re + u_re, ec_im + u_im)
    return rs_re, rs_im, rp_re, rp_im


def fresnel_mueller_entries(rs_re, rs_im, rp_re, rp_im):
    """Entries (a, b, c, s) of the facet Mueller matrix (paper Eq. 11, gamma = 0).

    In the facet s/p bases the Mueller matrix of a specular reflection is::

        [[a, b, 0,  0],
         [b, a, 0,  0],
         [0, 0, c, -s],
         [0, 0, s,  c]]

    with a = (|r_s|^2 + |r_p|^2)/2, b = (|r_s|^2 - |r_p|^2)/2,
    c = Re(r_p r_s*), s = Im(r_p r_s*): the same matrix as Mitsuba's
    ``mueller::specular_reflection`` (its c cos(delta), c sin(delta)).
    """
    rs2 = rs_re * rs_re + rs_im * rs_im
    rp2 = rp_re * rp_re + rp_im * rp_im
    a = 0.5 * (rs2 + rp2)
    b = 0.5 * (rs2 - rp2)
    c = rp_re * rs_re + rp_im * rs_im
    s = rp_im * rs_re - rp_re * rs_im
    return a, b, c, s


def fresnel_average(cos_beta, n, k):
    """Unpolarized facet reflectance M00(beta; eta) = (|r_s|^2 + |r_p|^2)/2 (paper Eq. 11, M00/2).

    The amplitudes of :func:`facet_fresnel` in real arithmetic, their squared moduli taken directly
    (|c - u|^2 / |c + u|^2 and |eta^2 c - u|^2 / |eta^2 c + u|^2 with u = eta cos(theta_t) = a - i b from
    the same cancellation-free square root): 41 traced operations in place of 70 (host cost per
    render and per instance, ``benchmarks/bench_render.py --instances``), the same float32 accuracy.
    """
    c = cos_beta
    sin2 = dr.maximum(1.0 - c * c, 0.0)
    nk = n * k
    e_re = (n - k) * (n + k)            # eta^2 = (n - ik)^2
    e_im = -2.0 * nk
    zr = e_re - sin2
    # u = sqrt(eta^2 - sin^2 beta) = a - i b, a, b >= 0: complex_sqrt_lower written out
    t1 = dr.sqrt(0.5 * (dr.sqrt(dr.fma(zr, zr, e_im * e_im)) + dr.abs(zr)))
    t2 = dr.abs(nk) / dr.maximum(t1, 1e-30)      # |Im z| / (2 t1); t1 = 0 only where z = 0, and then nk = 0
    zr_pos = zr >= 0
    a = dr.select(zr_pos, t1, t2)
    b = dr.select(zr_pos, t2, t1)
    b2 = b * b
    cm, cp = c - a, c + a
    rs2 = dr.fma(cm, cm, b2) / dr.fma(cp, cp, b2)
    p_re, p_im = e_re * c, e_im * c                 # eta^2 cos beta
    pm, pp = p_re - a, p_re + a
    rp2 = dr.fma(pm, pm, dr.square(p_im + b)) / dr.fma(pp, pp, dr.square(p_im - b))
    return 0.5 * (rs2 + rp2)


#: G1(a) = a (2 sqrt(pi) + p1 a + ... + p5 a^5) / (1 + q1 a + ... + q6 a^6) on [0, G1_A_MAX], 1 beyond:
#: fitted to the closed form by tools/fit_smith_g1.py (max relative error 1.3e-7, float32's rounding)
G1_NUM = (-0.010827622920133277, 1.1198086147653181, 0.13367879149690562, 0.1072509449449645, 0.04296867782887565)
G1_DEN = (1.769389500014301, 1.3107040943585058, 0.5928769949986893, 0.25218951682420315, 0.09301892441962625,
          0.043680588969694074)
G1_A_MAX = 4.3
_TWO_SQRT_PI = 3.5449077018110318


def smith_g1_exact(v, m, alpha):
    """Smith's masking G1(v, m) of the Beckmann distribution, 2 / (1 + erf(a) + exp(-a^2) / (a sqrt(pi))),
    a = cos(theta_v) / (alpha sin(theta_v)), to float32 precision; 0 where ``v`` sees the back of ``m``
    (v.m v.z <= 0), 1 along the normal.

    Evaluated as a rational function of a (:data:`G1_NUM`, :data:`G1_DEN`: relative error <= 1.3e-7 against
    the closed form in float64, tools/fit_smith_g1.py; beyond a = 4.3, 1 - G1 < 2e-11 and it is 1): Dr.Jit's
    erf and exp trace 145 operations per call, the rational function 14, and every operation is traced
    again for every instance at every render (the cost per instance).

    Mitsuba's ``MicrofacetDistribution.smith_g1`` is a coarser rational fit (up to 0.31 % off, at
    a = 0.56 and 1.34), while Mitsuba's visible-normal sampler draws from the density that the *exact*
    G1 normalizes: a pdf written with that fit is off the sampled density by that much, and so is every
    sampling weight (measured: the mean weight of roughconductor's ``sample`` is 0.3 % above its
    ``eval``'s integral at theta 75 deg, alpha 0.54).
    """
    xy2 = dr.fma(v.x, v.x, v.y * v.y)
    # a in [0, G1_A_MAX]: below the horizon a = 0 (zeroed below), along the normal (xy2 = 0) the clamp (G1 = 1)
    a = dr.clip(v.z * dr.rsqrt(dr.maximum(xy2, 1e-30)) / alpha, 0.0, G1_A_MAX)
    num = G1_NUM[-1]
    for c in G1_NUM[-2::-1]:
        num = dr.fma(num, a, c)
    den = G1_DEN[-1]
    for c in G1_DEN[-2::-1]:
        den = dr.fma(den, a, c)
    g = a * dr.fma(num, a, _TWO_SQRT_PI) / dr.fma(den, a, 1.0)
    return dr.select(dr.dot(v, m) * v.z <= 0.0, 0.0, dr.select(a < G1_A_MAX, g, 1.0))


def vgroove_g(wi, wo, h):
    """Torrance-Sparrow V-groove shadowing/masking (paper Eq. 12), vector form.

    G = min(1, 2 (n.h)(n.wo)/(wo.h), 2 (n.h)(n.wi)/(wi.h)) with n = +z, cos(alpha) = n.h and
    cos(beta) = wi.h = wo.h (h is the half vector of wi and wo, or the normal wo is reflected about):
    G = min(1, 2 h.z min(wi.z, wo.z) / wi.h), one dot product and one division.  Returns 0 where a
    direction is below the horizon or sees the back of the facet.
    """
    cos_b = dr.dot(wi, h)
    valid = (cos_b > 0) & (wi.z > 0) & (wo.z > 0)
    # the select keeps the division finite where the result is discarded anyway
    g = 2.0 * h.z * dr.minimum(wi.z, wo.z) / dr.select(valid, cos_b, 1.0)
    return dr.select(valid, dr.minimum(g, 1.0), 0.0)


_LOOKUP_CLASSES: dict = {}


class DHRLookup:
    """1 - rho^{s,PEC}(theta_i, rms_slope) (paper Eqs. 14-16) read through a Dr.Jit texture.

    The data is the model's shipped texture (:func:`hyde_bsdf.model.dhr.load_texture`, a
    :class:`~hyde_bsdf.model.dhr.DHRTexture`): 1 - rho resampled from the DHR table's bicubic
    spline onto nodes uniform in x = 1 - sqrt(cos theta) (dense near grazing, where rho varies
    most) and in ln(rms_slope) over the table's whole range (``parameters.DHR_TABLE_RMS_SLOPE``),
    float32.  It is held in an ``mi.Texture2f`` with linear filtering and clamped borders.  Linear
    filtering keeps the lookup differentiable w.r.t. rms_slope.  1 - rho_avg(rms_slope) (for the
    reciprocal diffuse term and the lobe choice) is an ``mi.Texture1f``.  ``use_accel=False`` keeps
    positional gradients on CUDA as well.  Interpolation error against the table's ``__call__``:
    ``hyde_bsdf/validation/plugin_checks.py`` ("DHR texture interpolation error").
    """

    def __new__(cls, texture=None):
        # Each variant gets a subclass whose DRJIT_STRUCT names that variant's texture types:
        # it makes the textures visible to Dr.Jit's traversal, so dr.freeze collects them as
        # inputs of a frozen function (without it: "virtual function call ... no such object
        # instance was found").  Built lazily: importing this module needs no variant.
        if "DRJIT_STRUCT" not in cls.__dict__:
            variant = mi.variant()
            if variant not in _LOOKUP_CLASSES:
                _LOOKUP_CLASSES[variant] = type(cls.__name__, (cls,), {
                    "DRJIT_STRUCT": {"tex": mi.Texture2f, "tex_avg": mi.Texture1f},
                    "__module__": cls.__module__})
            cls = _LOOKUP_CLASSES[variant]
        return object.__new__(cls)

    def __init__(self, texture=None):
        if texture is None:   # Dr.Jit's traversal may construct an empty instance
            return
        self.log_lo, self.log_hi = texture.log_lo, texture.log_hi
        self.nt, self.ns = texture.one_minus.shape
        self.host = texture          # the NumPy data, for :meth:`column`
        self.tex = mi.Texture2f(mi.TensorXf(aligned_float32(texture.one_minus.ravel()), shape=(self.nt, self.ns, 1)),
                                use_accel=False, filter_mode=dr.FilterMode.Linear,
                                wrap_mode=dr.WrapMode.Clamp)
        self.tex_avg = mi.Texture1f(mi.TensorXf(aligned_float32(texture.one_minus_avg), shape=(self.ns, 1)),
                                    use_accel=False, filter_mode=dr.FilterMode.Linear,
                                    wrap_mode=dr.WrapMode.Clamp)

    def slope_coord(self, rms_slope):
        """Texture coordinate of rms_slope along the ln(rms_slope) axis (texel-centred)."""
        t = (dr.log(rms_slope) - self.log_lo) / (self.log_hi - self.log_lo)
        return (t * (self.ns - 1) + 0.5) / self.ns

    def one_minus_rho(self, cos_theta, u_slope):
        """1 - rho^{s,PEC} at polar angle acos(cos_theta) and slope coordinate u_slope."""
        # x = 1 - sqrt(cos theta); the max keeps sqrt real for slightly negative rounding (cos theta <= 1
        # for a unit vector; 1 + eps lands below the first texel centre, read as x = 0 by the clamped border)
        x = 1.0 - dr.sqrt(dr.maximum(cos_theta, 0.0))
        v = (x * (self.nt - 1) + 0.5) / self.nt
        return self.tex.eval(mi.Point2f(u_slope, v))[0]

    def one_minus_rho_avg(self, u_slope):
        """1 - rho_avg(rms_slope), rho_avg = 2 int rho cos sin dtheta (reciprocal diffuse term)."""
        return self.tex_avg.eval(mi.Point1f(u_slope))[0]

    def column(self, rms_slope):
        """(1 - rho at the texture's x nodes, 1 - rho_avg) at one roughness, as NumPy float64 arrays: the
        texture interpolated linearly along ln(rms_slope) as its own lookup does (clamped at the ends)."""
        pos = (math.log(rms_slope) - self.log_lo) / (self.log_hi - self.log_lo) * (self.ns - 1)
        j = min(max(int(math.floor(pos)), 0), self.ns - 2)
        w = min(max(pos - j, 0.0), 1.0)
        cols = self.host.one_minus[:, j:j + 2].astype(np.float64)
        avg = self.host.one_minus_avg[j:j + 2].astype(np.float64)
        return (1.0 - w) * cols[:, 0] + w * cols[:, 1], float((1.0 - w) * avg[0] + w * avg[1])


class DHRSlice:
    """A function of the polar angle tabulated on the DHR texture's x nodes (x = 1 - sqrt(cos theta)): the
    diffuse term's factor at one constant roughness (:meth:`DHRLookup.column`, scaled by the term).

    Read by linear interpolation from flat arrays of the node values and of their differences to the next
    node (computed in float64), two gathers per lookup: a 2-D texture lookup traces about 50 operations,
    this one 8, and every traced operation is paid again for every instance at every render.  The values
    are those of the 2-D lookup at that roughness up to float32 rounding.
    """

    def __init__(self, values):
        values = np.asarray(values, dtype=np.float64)
        self.nt = len(values)
        self.data = mi.Float(aligned_float32(values))
        # the last node (x = 1, theta = 90 deg) has no successor: difference 0
        self.delta = mi.Float(aligned_float32(np.append(np.diff(values), 0.0)))

    def __call__(self, cos_theta):
        # (1 - sqrt(cos theta)) (nt - 1) in [0, nt - 1]; cos theta is clipped (1 + eps, and inactive lanes)
        pos = dr.fma(dr.sqrt(dr.clip(cos_theta, 0.0, 1.0)), 1.0 - self.nt, self.nt - 1.0)
        i = mi.UInt32(pos)
        return dr.fma(pos - mi.Float(i), dr.gather(mi.Float, self.delta, i), dr.gather(mi.Float, self.data, i))
