"""The ``hyde`` BSDF: Hyde-Schmidt-Havrilla (2009) pBRDF as a Mitsuba 3 plugin.

Call :func:`register` (also exposed as ``hyde_bsdf.register()``): with no argument it
registers ``hyde`` in every usable variant (set the variant before or after), with a
variant name only in that one (an unusable variant, e.g. ``cuda_*`` without a GPU,
raises an error naming the ``llvm_*`` variant to use instead).  Then ``{'type': 'hyde', ...}`` / ``<bsdf type="hyde">``
works.  The parameter table and the conventions are in :data:`DOC` (which is also the
class docstring).
"""
from __future__ import annotations

import math
import threading

import drjit as dr
import mitsuba as mi
import numpy as np

from hyde_bsdf.errors import UsageError, UsageTypeError, shorten
from hyde_bsdf.io.ior import material_files
from hyde_bsdf.mitsuba import optics as po
from hyde_bsdf.mitsuba import param_checks as pc
from hyde_bsdf.mitsuba import stokes as ps
from hyde_bsdf.model import terms
from hyde_bsdf.model.parameters import ALPHA, DHR_TABLE_RMS_SLOPE, DIFFUSE_REFLECTANCE, ETA, INDEX_MIN, RMS_SLOPE, SQRT2

__all__ = ["register", "plugin_class", "DOC"]

DOC = r"""Hyde-Schmidt-Havrilla polarimetric rough-surface BRDF (``hyde``).

.. list-table::
   :header-rows: 1

 * - Parameter
   - Type
   - Default
   - Meaning and range
   - Traverse key / differentiable
 * - rms_slope
   - float or texture
   - 0.3 (if no roughness is given)
   - the paper's roughness sqrt(2) sigma_h / ell (rms facet slope along one axis),
     per shading point (texture ``eval_1(si)``, like roughconductor's alpha);
     useful range 0.02-1.5; accepted @RMS_SLOPE@, with every diffuse term
     (values in [0, @RMS_LO@) are floored to @RMS_LO@ with a warning)
   - ``rms_slope.value`` (float), ``rms_slope.data`` (bitmap), ``rms_slope.color0.value``
     (checkerboard), ...; differentiable, discontinuous
 * - alpha
   - float or texture
   - (none)
   - Beckmann alpha = sqrt(2) rms_slope = 2 sigma_h / ell (roughconductor's alpha);
     alternative to rms_slope; accepted @ALPHA@; values in
     [0, @ALPHA_LO@) (roughconductor's mirror, alpha = 0) are floored with a warning
   - ``alpha.value`` / ``alpha.data`` / ...: Beckmann alpha, as roughconductor;
     differentiable, discontinuous
 * - sigma_h, ell
   - float, float (scalars only: use rms_slope or alpha for a texture)
   - (none)
   - rms surface height and Gaussian correlation length (same units, both needed);
     alternative to rms_slope
   - ``rms_slope.value`` (stored as rms_slope = sqrt(2) sigma_h / ell)
 * - eta, k
   - float, spectrum, rgb or texture
   - 0, 1 (a 100 % reflective mirror, as roughconductor)
   - real and imaginary part of the complex index n + i k (Mitsuba's sign;
     the paper writes the same material as eta = n - j kappa); eta and k in
     @INDEX@ (``parameters.ETA``), not both 0.  ``k = 0`` with any eta is a dielectric (dispersive if eta is a
     spectrum).
   - ``eta.value``, ``k.value`` (float; ``eta.values`` for a spectrum, ``eta.data``
     for a bitmap); differentiable, discontinuous
 * - material
   - string
   - (none)
   - a named metal from Mitsuba's ``data/ior`` tables ("Au", "Al", "Cu", "Ag", ...);
     alternative to eta/k; "none" (roughconductor's spelling) means eta/k.  Spectral variants use the tabulated spectrum, RGB
     variants its unbounded sRGB, mono variants its luminance, as Mitsuba's own
     conductors do
   - ``eta.values`` + ``eta.wavelengths`` (spectral), ``eta.value`` (RGB: a Color3f;
     mono: a Float); the same under ``k.``; differentiable
 * - specular_reflectance
   - float, spectrum or texture
   - 1.0
   - multiplier of the specular lobe and the paper's diffuse term, as roughconductor's;
     not physical: keep it 1 for the paper's model
   - ``specular_reflectance.value`` / ``.data``; differentiable
 * - diffuse_reflectance
   - float, spectrum or texture (only with ``diffuse="lambertian"``)
   - 0.5 (Mitsuba's)
   - albedo of the Lambertian diffuse term: f_00 += diffuse_reflectance / pi, unpolarized, its
     size free (not the paper's term, whose size the roughness fixes), as in Mitsuba's
     plastic-like BSDFs; in @ALBEDO@
   - ``diffuse_reflectance.value`` / ``.data``; differentiable
 * - distribution
   - string
   - "beckmann"
   - only "beckmann": the paper's model is Beckmann and isotropic ("ggx", alpha_u / alpha_v
     are refused with that reason)
   - no
 * - shadowing
   - string
   - "vgroove"
   - shadowing/masking G: "vgroove" (paper Eq. 12, Torrance-Sparrow/Blinn),
     "smith" (Beckmann Smith G1 product: with diffuse="none" or "lambertian" Mitsuba's
     rational approximation, as roughconductor; with "paper" or "reciprocal" the exact G1
     whose DHR the diffuse term reads), "none" (G = 1: the albedo exceeds 1 at grazing angles, one warning
     when it does at the material's roughness)
   - no
 * - diffuse
   - string
   - "reciprocal" ("paper" with shadowing="none", which "reciprocal" refuses)
   - the unpolarized diffuse term: "reciprocal" = (1 - rho(theta_i))(1 - rho(theta_o)) M00(beta) /
     (pi (1 - rho_avg)), the default: white-furnace albedo <= 1 in both transport modes;
     "paper" = Eq. 17 as written, (1/pi) (1 - rho(theta_in)) M00(beta): in a path tracer
     (radiance mode) its albedo is rho(theta) + 1 - rho_avg, up to 1.94 at grazing angles
     (hyde_bsdf/validation/furnace.py); "none" = specular lobe only; "lambertian" = diffuse_reflectance / pi
     (its own albedo)
   - no
 * - sample_visible
   - bool ("true"/"false" strings are parsed)
   - true
   - sample the specular lobe from the visible normals of the shadowing (Heitz & d'Eon 2014): the
     V-cavity's with "vgroove", Smith's otherwise; false: from D cos theta_h
   - no

Validation (:mod:`hyde_bsdf.mitsuba.param_checks`).  The constructor and every
``params.update()`` (``parameters_changed``, to the parameters the update changed: an
optimisation loop over a roughness map pays one small check kernel per update) apply the same
checks, on the values the textures' own ``eval`` returns (an 8-bit PNG is read as 0-1, not as its stored 0-255): the roughness
finite and in range (values in [0, lower bound) floored with a warning), eta and k finite and
in @INDEX@ and not both 0 for a constant, specular_reflectance finite and >= 0,
diffuse_reflectance finite and in @ALBEDO@; constants at
48 wavelengths 360-830 nm (spectral), every texel of a bitmap and both colours of a
checkerboard.  A refused update restores the last accepted values (the update is atomic).
Values that cannot be read at load (a ``mesh_attribute`` or procedural texture) get one
warning and are clamped at eval (roughness to its range, eta and k to @INDEX@,
specular_reflectance and diffuse_reflectance to [0, 1], NaN: no reflection).  Where a spectrum is 0 (outside the
wavelength range it is defined on, Mitsuba's rule) and k is 0 as well, the index is taken as 1
(no reflection) rather than producing 0/0, with a warning at load (spectral variants: give eta
over 360-830 nm).

Model.  f = D(h) M(beta; eta) G / (4 cos theta_i cos theta_o)  +  diffuse (paper
Eqs. 6, 8, 11, 12, 13, 17), where D is the Beckmann distribution with
alpha = sqrt(2) rms_slope (identical to the paper's Eq. 8 divided by cos alpha),
h = normalize(wi + wo) the facet normal, cos beta = wi.h, and M the facet Fresnel
Mueller matrix rotated from the facet s/p bases into Mitsuba's Stokes bases.
``eval`` returns f cos(theta_o) (Mitsuba's convention); the BSDF is one-sided.
rho = rho^{s,PEC}(theta, rms_slope) is the directional-hemispherical reflectance
of the specular lobe of a perfect conductor (Eqs. 14-16) for the chosen
shadowing, read from the package's shipped table (:func:`hyde_bsdf.model.dhr.load_texture`)
through a Dr.Jit texture.

Frames (as ``roughconductor``).  All vectors are in the local shading frame
(normal +z).  Light arrives along ``-wo_hat`` and leaves along ``+wi_hat``, where
(wo_hat, wi_hat) = (wo, si.wi) in Radiance mode and (si.wi, wo) in Importance
mode.  The Mueller matrix maps Stokes vectors in ``stokes_basis(-wo_hat)`` to
Stokes vectors in ``stokes_basis(wi_hat)``.  The paper's omega_i (toward the
source) is ``wo_hat`` and its omega_r (toward the observer) is ``wi_hat``.

Non-reciprocal diffuse term.  In ``diffuse="paper"`` theta_in is the polar angle
of the direction the light arrives from, i.e. of ``wo_hat`` (``wo`` in Radiance
mode, ``si.wi`` in Importance mode), so light and importance transport see the
same physical BRDF.  ``diffuse="reciprocal"`` is symmetric in the two directions.

Stokes sign convention.  Mitsuba's Stokes vectors use the reference axis
x = ``stokes_basis(k)`` with y = k x x, and the same S0..S3 definitions as the
paper's bases (s, p, k) with S3 = -2 Im(E_s E_p*) for e^{+j w t}: rotating
Mitsuba's bases into the paper's (``mi.mueller.rotate_mueller_basis``, see
:mod:`hyde_bsdf.validation._frames`) reproduces all 16 elements of
:func:`hyde_bsdf.pbrdf`, S3 rows and columns included - no sign conversion is
needed at this boundary.  At normal incidence r_p = -r_s (Mitsuba's Fresnel
signs), so a mirror gives F00 diag(1, 1, -1, -1) in the paper's bases.

Facet frame.  The facet's s axis (perpendicular to its plane of incidence) is
wo_hat x wi_hat, parallel to roughconductor's cross(h, -wo_hat), but computed with
a compensated (Kahan) cross product: near backscatter the plain float32 product
tilts the Stokes frame by ~eps/|wi x wo| (roughconductor is off the float64
evaluator by up to 3e-5 there, this plugin by < 2e-6).  Every normalisation has a named
fallback where float32 cannot normalise: "collinear" (the s axis through
:func:`hyde_bsdf.mitsuba.optics.safe_normalize`: wo_hat parallel to wi_hat to float32
precision, backscatter or both along the normal; the facet is then at normal incidence,
where its Mueller matrix does not depend on the s axis, and s = stokes_basis(-wo_hat))
and "opposite" (|wi + wo| < 1e-15, both within 1e-15 of the horizon: no half vector, the
pair reflects nothing).  Directions within
1e-15 of the normal are snapped onto it before Mitsuba's Smith G1, which is NaN there
(roughconductor too); D G / (4 cos theta_i) and its pdf are capped at MAX_LOBE = 1e30.
No direction pair gives NaN (tests: 1e-38 ... 1e-3 from the normal and from each other).

Index.  Textures of eta and k are evaluated per wavelength (spectral), per RGB
channel (unbounded sRGB) or as luminance (mono); like Mitsuba, |k| is used.
Roughness textures are evaluated once per call (``eval_1``) and the DHR lookup of
the diffuse term is done at that per-point roughness.

DHR lookup.  1 - rho^{s,PEC}, resampled from the table's bicubic ``__call__``
onto 1025 nodes in x = 1 - sqrt(cos theta) times 192 per decade of rms_slope over
the table's whole range @DHR_TABLE@ (4.7 MB, float32), is shipped with the package
(``hyde_bsdf/data/dhr_texture_{vgroove,smith,none}.npz``: nothing is computed at load) and read with a linear
``mi.Texture2f`` (differentiable in rms_slope), at each shading point's own roughness.
Its deviation from the table, 1 - rho clipped at 0, for rms_slope in @RMS_SLOPE@ and
theta <= 89 deg is <= 1.9e-5 (vgroove), 2.6e-5 (smith), 1.3e-4 (none), target 2e-4
(``hyde_bsdf/validation/plugin_checks.py``, "DHR texture interpolation error"); denser grids
cost render time once the roughness varies per point (cache misses).  1 - rho is
clipped at 0 (rho > 1 happens without shadowing near grazing).  A constant roughness (a number whose
value needs no gradient) reads instead a 1-D table of the diffuse factor over the polar angle at that
roughness, cut from the same texture at load and at each update (8 kB per material): one interpolation
per direction in place of a 2-D lookup, the same values to float32 rounding; every traced operation
is paid again for every instance at every render (the cost per instance, benchmarks/bench_render.py).

Sampling.  With probability p_spec the specular lobe is sampled from the
visible Beckmann normals of the shadowing, otherwise a cosine hemisphere.  With "vgroove" these are
the V-cavity's, exact (Heitz & d'Eon 2014): a normal from D cos theta_m, then it or its mirror
image, the cavity's other face, in proportion to their projected areas; the density is D G1 wi.m /
cos theta_i with the V-cavity's G1, whose minimum over the two directions is Eq. 12's G, so the
sampling weight is <= F (a fifth of the traced operations of Smith's).  With "smith" and "none"
they are Smith's (``mi.MicrofacetDistribution``).  p_spec = clamp(rho_avg, 0.05, 0.95),
rho_avg = 2 int rho cos sin dtheta (the 1-D texture of the reciprocal term): the ratio of the
specular albedo rho F to rho F + (1 - rho) F (F common to both lobes) averaged over the incidence angle; one
1-D lookup in place of a second 2-D one into the DHR texture (any p_spec in (0, 1)
that the pdf also uses is unbiased); p_spec = 1 when ``diffuse="none"`` (then, with "smith", ``sample``
equals roughconductor's).  ``pdf`` and ``eval_pdf`` return the mixture density.

Components: 0 = glossy reflection (specular lobe), 1 = diffuse reflection.
"""
# the ranges in the table above, from the registry (hyde_bsdf.model.parameters)
for _token, _text in (("@RMS_SLOPE@", RMS_SLOPE.text()), ("@RMS_LO@", f"{RMS_SLOPE.lo:.7g}"),
                      ("@ALPHA@", ALPHA.text()), ("@ALPHA_LO@", f"{ALPHA.lo:.7g}"),
                      ("@INDEX@", f"[0, {ETA.hi:.0e}]".replace("e+0", "e")),
                      ("@DHR_TABLE@", DHR_TABLE_RMS_SLOPE.text()), ("@ALBEDO@", DIFFUSE_REFLECTANCE.text())):
    DOC = DOC.replace(_token, _text)


def _read_float(props, name, hint=""):
    """A finite scalar property (``hint``: added to the message of a non-number)."""
    value = props.get(name)
    try:
        value = float(value)
    except (TypeError, ValueError):
        raise UsageTypeError(f"hyde: parameter '{name}' must be a number{hint}, got {shorten(value)}") from None
    if not math.isfinite(value):
        raise UsageError(f"hyde: parameter '{name}' must be finite, got {value!r}")
    return value


def _read_bool(props, name, default):
    """A boolean property; the strings "true"/"false" (any case) are parsed, others refused."""
    if name not in props:
        return default
    value = props.get(name)
    if isinstance(value, bool):
        return value
    if isinstance(value, str) and value.strip().lower() in ("true", "false"):
        return value.strip().lower() == "true"
    raise UsageTypeError(f"hyde: parameter '{name}' must be a boolean (true or false), got {shorten(value)}")


def _ior_texture(path):
    """A texture holding the spectrum in a Mitsuba ``.spd`` file, converted as ior.h does."""
    wavelengths, values = mi.spectrum_from_file(path)
    if mi.is_spectral:
        return mi.load_dict({"type": "irregular",
                             "wavelengths": ", ".join(repr(float(w)) for w in wavelengths),
                             "values": ", ".join(repr(float(v)) for v in values)})
    color = mi.spectrum_list_to_srgb(wavelengths, values, False, False)
    if mi.is_monochromatic:
        return mi.load_dict({"type": "uniform",
                             "value": float(np.asarray(mi.luminance(color), dtype=float).ravel()[0])})
    return mi.load_dict({"type": "srgb", "color": color, "unbounded": True})


# ---------------------------------------------------------------- texture checks
def _texture(props, name, default):
    """``props.get_unbounded_texture`` with Mitsuba's own refusal as a one-line UsageError."""
    try:
        return props.get_unbounded_texture(name, default)
    except RuntimeError as exc:   # e.g. an all-zero spectrum: "no probability mass found"
        last = str(exc).strip().splitlines()[-1]
        raise UsageError(f"hyde: parameter '{name}' is refused by Mitsuba ({last}); an index with "
                         f"eta and k both 0 is not a material") from None


def _describe(tex):
    """A constant texture's value as a number (e.g. ``0.3``), else the texture's own string."""
    data = pc.texture_data(tex)
    if list(data) == ["value"] and data["value"].size == 1:
        return f"{float(data['value'][0]):.6g}"
    return str(tex)


def _warn_unreadable(name, tex, clamp):
    """One warning per texture whose values cannot be read at load (clamped at eval instead)."""
    import warnings

    if not pc.readable(tex):
        warnings.warn(f"hyde: the values of {name} ({tex.class_name()}) cannot be read at load; "
                      f"they are clamped to {clamp} at evaluation (NaN: no reflection)",
                      RuntimeWarning, stacklevel=5)
        return True
    return False


_DHR_CACHE: dict = {}


def _dhr_lookup(shadowing):
    """One DHRLookup per (variant, shadowing), shared by all instances: the shipped texture
    (:func:`hyde_bsdf.model.dhr.load_texture`), nothing computed at load."""
    key = (mi.variant(), shadowing)
    if key not in _DHR_CACHE:
        from hyde_bsdf.model.dhr import load_texture

        _DHR_CACHE[key] = po.DHRLookup(load_texture(shadowing))
    return _DHR_CACHE[key]


#: Upper bound of the specular lobe's D G / (4 cos theta_i) and of its pdf.  A near-mirror
#: (alpha 1.4e-4: D(0) = 1.6e7) seen at cos theta_i < 1e-31 would overflow float32 to Inf (and
#: Inf * 0 = NaN in the Mueller entries); no physical radiance comes near this bound.
MAX_LOBE = 1e30


#: below this length wi + wo has no direction in float32 (``_half_vector``: its squared norm would lose components)
MIN_HALF = 1e-15


def _pos(x):
    """A denominator that is > 0 on every lane whose result is kept: 1 elsewhere.

    Those lanes are masked out afterwards; the guard keeps them from producing Inf/NaN
    (which would leak into gradients) and scalar variants from raising ZeroDivisionError.
    """
    return dr.select(x > 0, x, 1.0)


_PARAMS = ("rms_slope", "alpha", "sigma_h", "ell", "eta", "k", "material", "specular_reflectance",
           "diffuse_reflectance", "distribution", "shadowing", "diffuse", "sample_visible")


# ---------------------------------------------------------------- constructor: reading the properties
def _refuse_outside_model(props):
    """The paper's model is isotropic Beckmann: another distribution or an anisotropic roughness is refused."""
    distribution = str(props.get("distribution", "beckmann")).lower()
    if distribution != "beckmann":
        raise UsageError(f"hyde: distribution={shorten(distribution)} is not supported: the paper's "
                         f"model uses the Beckmann distribution only (isotropic)")
    aniso = [x for x in ("alpha_u", "alpha_v") if x in props]
    if aniso:
        raise UsageError(f"hyde: {'/'.join(aniso)} (anisotropic roughness) is not supported: the "
                         f"paper's model is isotropic Beckmann; give one alpha or rms_slope")


def _sigma_h_ell_rms(props):
    """rms_slope = sqrt(2) sigma_h / ell from the scalar pair sigma_h, ell (both > 0, given together)."""
    missing = [x for x in ("sigma_h", "ell") if x not in props]
    if missing:
        raise UsageError(f"hyde: sigma_h and ell must be given together; missing {missing[0]}")
    hint = " (sigma_h and ell are scalars; give rms_slope or alpha for a texture)"
    sh, ell = _read_float(props, "sigma_h", hint), _read_float(props, "ell", hint)
    if sh <= 0 or ell <= 0:
        raise UsageError(f"hyde: sigma_h and ell must be > 0, got sigma_h={sh}, ell={ell}")
    rms = SQRT2 * sh / ell
    if not RMS_SLOPE.contains(rms):
        raise UsageError(f"hyde: sigma_h/ell give rms_slope = sqrt(2) sigma_h/ell = {rms:g}; "
                         f"the accepted range is [{RMS_SLOPE.lo:g}, {RMS_SLOPE.hi:g}]")
    return rms


def _read_roughness(props):
    """(traverse name, texture) of the roughness, given as exactly one of rms_slope, alpha (Beckmann alpha,
    a texture each) or the scalars sigma_h+ell (kept as an rms_slope); default rms_slope 0.3."""
    groups = [g for g, names in (("rms_slope", ("rms_slope",)), ("alpha", ("alpha",)),
                                 ("sigma_h+ell", ("sigma_h", "ell")))
              if any(x in props for x in names)]
    if len(groups) > 1:
        raise UsageError(f"hyde: give the roughness as exactly one of rms_slope, alpha or "
                         f"sigma_h+ell; got conflicting {', '.join(groups)}")
    if "sigma_h" in props or "ell" in props:
        return "rms_slope", props.get_texture("rms_slope", _sigma_h_ell_rms(props))
    key = "alpha" if "alpha" in props else "rms_slope"
    if key in props and props.type(key) == mi.Properties.Type.Float:
        _read_float(props, key)  # finite number (the range check follows)
    return key, props.get_texture(key, 0.3)


def _read_index(props):
    """(eta, k, material name or None): the spectra of a Mitsuba ``data/ior`` material, or the eta/k
    textures (default eta 0, k 1); "none" is roughconductor's spelling of "eta/k given"."""
    material = str(props.get("material", "none")) if "material" in props else "none"
    if material.lower() == "none":
        for name in ("eta", "k"):
            if name in props and props.type(name) == mi.Properties.Type.Float:
                _read_float(props, name)
        return _texture(props, "eta", 0.0), _texture(props, "k", 1.0), None
    given = [x for x in ("eta", "k") if x in props]
    if given:
        raise UsageError(f"hyde: give either material or eta/k, not both "
                         f"(got material and {', '.join(given)})")
    try:
        eta_file, k_file = material_files(material)     # data/ior names only (no ../)
    except ValueError as exc:
        raise UsageError(f"hyde: {exc}") from None
    return _ior_texture(str(eta_file)), _ior_texture(str(k_file)), material


def _read_terms(props):
    """(shadowing record, diffuse record) of :mod:`hyde_bsdf.model.terms`, checked against its rules
    (a boolean ``diffuse`` means "paper" or "none"); a term without a Dr.Jit implementation here is refused."""
    shadowing = str(props.get("shadowing", terms.RENDER_DEFAULT[0])).lower()
    diffuse = props.get("diffuse", None)
    if diffuse is None:     # the renderers' default; the paper's term where the rule refuses it (shadowing="none")
        diffuse = terms.RENDER_DEFAULT[1]
        if shadowing in terms.SHADOWING and not terms.allowed(shadowing, diffuse):
            diffuse = terms.DIFFUSE[0]
    if not isinstance(diffuse, bool):  # <boolean name="diffuse" .../> also accepted
        diffuse = str(diffuse).lower()
    try:
        shadow, term = terms.check_pair(shadowing, diffuse)
    except UsageError as exc:
        raise UsageError(f"hyde: {exc}") from None
    for kind, record, table in (("shadowing", shadow, _SHADOWING), ("diffuse", term, _DIFFUSE)):
        if record.name not in table:
            raise UsageError(f"hyde: {kind}={record.name!r} has no Dr.Jit implementation in the plugin; "
                             f"use one of {', '.join(table)}")
    return shadow, term


# ---------------------------------------------------------------- the terms, in Dr.Jit (keyed by record name)
# Independent derivations of the records' NumPy functions (model/shadowing.py, model/diffuse.py).
def _g_vgroove(distr, wi, wo, h):
    return po.vgroove_g(wi, wo, h)


def _g_smith(distr, wi, wo, h):
    """Mitsuba's G (its rational fit of G1, as roughconductor): shadowing="smith", diffuse="none"."""
    # directions within 1e-15 of the normal: see optics.snap_to_normal (Mitsuba's G is NaN there)
    return distr.G(po.snap_to_normal(wi), po.snap_to_normal(wo), h)


def _g_smith_exact(distr, wi, wo, h):
    """G1(wi) G1(wo) with the exact G1: with a diffuse term, whose DHR table is that of the exact G."""
    return po.smith_g1_exact(wi, h, distr.alpha()) * po.smith_g1_exact(wo, h, distr.alpha())


def _g_none(distr, wi, wo, h):
    # G = 1, but still only facets seen from the front by both directions
    return dr.select((dr.dot(wi, h) > 0) & (dr.dot(wo, h) > 0), 1.0, 0.0)


def _smith_visible_ratio(distr, wi, wo, m):
    """G / G1(wi) of the uncorrelated Smith G = G1(wi) G1(wo): G1(wo), as roughconductor writes it."""
    return distr.smith_g1(po.snap_to_normal(wo), m)


def _smith_visible_ratio_exact(distr, wi, wo, m):
    return po.smith_g1_exact(wo, m, distr.alpha())


def _g1_fit(distr, v, m):
    """Mitsuba's G1 (rational fit): roughconductor's visible-normal density, bias and all."""
    return distr.smith_g1(po.snap_to_normal(v), m)


def _g1_exact(distr, v, m):
    """The exact G1: the density Mitsuba's visible-normal sampler draws from (optics.smith_g1_exact)."""
    return po.smith_g1_exact(v, m, distr.alpha())


def _g1_vcavity(distr, v, m):
    """The V-cavity masking of one direction (Heitz 2014, JCGT 3(2)), G1(v, m) = min(1, 2 cos theta_m cos
    theta_v / v.m), 0 where ``v`` sees the back of ``m``: min(G1(wi, h), G1(wo, h)) is the V-groove G of paper
    Eq. 12, and D G1(wi, m) (wi.m)+ / cos theta_i the density :func:`_sample_vcavity` draws from."""
    v_m = dr.dot(v, m)
    front = v_m > 0
    return dr.select(front, dr.clip(2.0 * m.z * v.z / dr.select(front, v_m, 1.0), 0.0, 1.0), 0.0)


def _sample_smith(distr, wi, sample2, u):
    """(m, its density): Mitsuba's sampler, the visible Smith normals (Heitz & d'Eon 2014) or D cos theta_m."""
    return distr.sample(po.snap_to_normal(wi), sample2)


def _sample_vcavity(distr, wi, sample2, u):
    """(m, its density): the visible normals of the V-cavity model, exactly (Heitz & d'Eon 2014, Comput. Graph.
    Forum 33(4), its V-cavity algorithm): m from D(m) cos theta_m (Mitsuba's sampler without visible normals),
    then m or its mirror m' = (-m.x, -m.y, m.z), the cavity's other face, with probability proportional to its
    projected area (wi.m)+ ; (wi.m)+ + (wi.m')+ >= 2 cos theta_i cos theta_m > 0.  D(m') = D(m), so the
    density of the chosen face is D cos theta_m 2 (wi.m)+ / ((wi.m)+ + (wi.m')+) = D G1(wi, m) (wi.m)+ /
    cos theta_i (:func:`_g1_vcavity`).  With the V-groove G the sampling weight G F / G1(wi) is <= F.  ``u``
    in [0, 1) chooses the face; 166 traced operations against 906 of the visible Smith normals."""
    m, pdf = mi.MicrofacetDistribution(mi.MicrofacetType.Beckmann, distr.alpha(), False).sample(wi, sample2)
    axial, lateral = wi.z * m.z, wi.x * m.x + wi.y * m.y
    a = dr.maximum(axial + lateral, 0.0)            # (wi.m)+
    b = dr.maximum(axial - lateral, 0.0)            # (wi.m')+
    total = a + b
    mirror = u * total >= a                         # probability b / (a + b)
    m = mi.Vector3f(dr.select(mirror, -m.x, m.x), dr.select(mirror, -m.y, m.y), m.z)
    ok = total > 0
    return m, dr.select(ok, 2.0 * pdf * dr.select(mirror, b, a) / dr.select(ok, total, 1.0), 0.0)


#: shadowing name -> (G(distr, wi, wo, h), the exact G / G1(wi) for visible-normal sampling or None,
#: G1(distr, v, m) of the visible-normal density, the visible-normal sampler (distr, wi, sample2, u in [0, 1))
#: -> (m, its density)).  "smith" without a diffuse term that reads the DHR ("none",
#: "lambertian") is roughconductor's lobe, sampling included: Mitsuba's rational G1 ("smith_fit"); every other
#: material uses the exact G1, in G (smith: the G whose DHR the diffuse term reads, so that specular + diffuse
#: albedo = 1) and in the density (the one the sampler draws from).  "vgroove" samples the visible normals of
#: its own masking, the V-cavity's: its weights are <= F and it traces a fifth of the operations
_SHADOWING = {"vgroove": (_g_vgroove, None, _g1_vcavity, _sample_vcavity),
              "smith": (_g_smith_exact, _smith_visible_ratio_exact, _g1_exact, _sample_smith),
              "smith_fit": (_g_smith, _smith_visible_ratio, _g1_fit, _sample_smith),
              "none": (_g_none, None, _g1_exact, _sample_smith)}


def _one_minus_clipped(dhr, cos_theta, u):
    # rho > 1 is possible without shadowing (Priest-Germer); 1 - rho is clipped at 0
    return dr.maximum(dhr.one_minus_rho(cos_theta, u), 0.0)


def _diffuse_paper(dhr, cos_in, cos_i, cos_o, u, one_minus_avg):
    """Eq. 17: (1/pi)(1 - rho(theta_in)), theta_in the direction the light arrives from."""
    return _one_minus_clipped(dhr, cos_in, u) * dr.inv_pi


def _diffuse_reciprocal(dhr, cos_in, cos_i, cos_o, u, one_minus_avg):
    """(1 - rho(theta_i))(1 - rho(theta_o)) / (pi (1 - rho_avg))."""
    # without shadowing rho_avg can reach 1: keep the division finite
    one_minus_avg = dr.maximum(one_minus_avg, 1e-30)
    return _one_minus_clipped(dhr, cos_i, u) * _one_minus_clipped(dhr, cos_o, u) * dr.inv_pi / one_minus_avg


def _slice_paper(one_minus, one_minus_avg):
    """Eq. 17's factor on the texture's nodes at one roughness, (1 - rho) / pi (1 - rho clipped at 0)."""
    return np.maximum(one_minus, 0.0) / math.pi


def _from_slice_paper(factor, cos_in, cos_i, cos_o):
    return factor(cos_in)


def _slice_reciprocal(one_minus, one_minus_avg):
    """The reciprocal term's factor of one direction, (1 - rho) / sqrt(pi (1 - rho_avg)): the term is the
    product of the two directions' factors."""
    return np.maximum(one_minus, 0.0) / math.sqrt(math.pi * max(one_minus_avg, 1e-30))


def _from_slice_reciprocal(factor, cos_in, cos_i, cos_o):
    return factor(cos_i) * factor(cos_o)


#: diffuse name -> (its factor (dhr, cos theta_in, cos theta_i, cos theta_o, slope coordinate, 1 - rho_avg): the
#: term without M00 and without cos theta_o; the same tabulated over the polar angle at one roughness from
#: (1 - rho at the texture's nodes, 1 - rho_avg), and the term from that table (an ``optics.DHRSlice``) and
#: (cos theta_in, cos theta_i, cos theta_o)), or None: "none" has no diffuse lobe; "lambertian" no factor of the
#: facet M00 -- its albedo texture, diffuse_reflectance / pi, is added unpolarized in ``_value``
_DIFFUSE = {"paper": (_diffuse_paper, _slice_paper, _from_slice_paper),
            "reciprocal": (_diffuse_reciprocal, _slice_reciprocal, _from_slice_reciprocal),
            "none": None, "lambertian": None}


def _read_albedo(props, term):
    """The ``diffuse_reflectance`` texture of a term that has it (default 0.5, Mitsuba's), else None;
    given with another diffuse term it is refused, naming the term that takes it."""
    if "diffuse_reflectance" in term.parameters:
        if "diffuse_reflectance" in props and props.type("diffuse_reflectance") == mi.Properties.Type.Float:
            _read_float(props, "diffuse_reflectance")
        return props.get_texture("diffuse_reflectance", terms.PARAMETER_DEFAULTS["diffuse_reflectance"])
    if "diffuse_reflectance" in props:
        raise UsageError(f"hyde: diffuse_reflectance is the albedo of diffuse='lambertian', not of "
                         f"diffuse={term.name!r}")
    return None


#: the albedo of shadowing="none" is checked up to this angle of incidence (deg), as hyde_bsdf/validation/furnace.py does
GAIN_THETA_DEG = 89.5
#: above 1 by more than the DHR table's interpolation error: an energy gain
GAIN_TOL = 2e-4


def _gain_warning(values, scale):
    """The warning of a shadowing="none" material whose albedo exceeds 1 at its roughness, or None.

    Without shadowing the specular lobe's DHR rho(theta) (paper Eq. 14) exceeds 1 at grazing incidence
    (Priest-Germer) and so does the albedo, whatever the diffuse term (it only adds to rho); rho at
    89.5 deg grows with roughness, so the largest value decides.  ``values``: the roughness values read
    at load or update (None: not readable), ``scale``: 1 for rms_slope, 1/sqrt(2) for alpha."""
    from hyde_bsdf.model.dhr import load_table

    advice = "use shadowing='vgroove' or 'smith' for a material that conserves energy (docs/plugin.md)"
    if values is None:
        return (f"hyde: shadowing='none' (no shadowing/masking) can reflect more light than it receives at "
                f"grazing incidence, and the roughness cannot be read at load to say where; {advice}")
    rms = float(np.clip(np.max(values) * scale, RMS_SLOPE.lo, RMS_SLOPE.hi))
    theta = np.radians(np.linspace(0.0, GAIN_THETA_DEG, 180))
    rho = load_table("none")(theta, rms)
    if rho.max() <= 1.0 + GAIN_TOL:
        return None
    onset = math.degrees(theta[np.argmax(rho > 1.0 + GAIN_TOL)])
    return (f"hyde: shadowing='none' (no shadowing/masking) reflects more light than it receives at grazing "
            f"incidence at rms_slope {rms:.3g}: its albedo exceeds 1 from {onset:.1f} deg on and reaches "
            f"{rho.max():.3g} at {GAIN_THETA_DEG:g} deg (hyde_bsdf/validation/furnace.py); {advice}")


def _achromatic(tex, params=None):
    """Whether ``tex`` is a ``uniform`` texture of one number (its ``eval_1`` is all of it); ``params``: its
    ``mi.traverse`` if already made."""
    try:
        params = mi.traverse(tex) if params is None else params
    except RuntimeError:
        return False
    return (list(params.keys()) == ["value"] and isinstance(params["value"], mi.Float)
            and not tex.is_spatially_varying())


def _refuse_unknown(props):
    """A property that no query read is not one of the plugin's parameters: refused, naming the accepted."""
    unknown = [x for x in props.unqueried() if x not in _PARAMS]
    if unknown:
        raise UsageError(f"hyde: unknown parameter(s) {', '.join(sorted(unknown))}; "
                         f"accepted: {', '.join(_PARAMS)}")


def _lobe_flags(diffuse):
    """(components, flags): component 0 the glossy specular lobe, 1 the diffuse term (if the record has one)."""
    comps = [mi.BSDFFlags.GlossyReflection | mi.BSDFFlags.FrontSide]
    if diffuse.present:
        comps.append(mi.BSDFFlags.DiffuseReflection | mi.BSDFFlags.FrontSide)
    flags = comps[0]
    for c in comps[1:]:
        flags = flags | c
    return comps, flags


class _Derived:
    """Values derived from a texture's constant value, traced once (at load and at each update) so that a
    traced call reads them instead of tracing their operations again: every live instance's methods are
    traced at every render, and those operations are the cost per instance.

    ``get()`` returns them only while they are what the call would compute: the texture still holds the
    variable they were computed from (an assignment ``params[key] = v`` puts a new one there; the copy held
    here keeps the old variable alive, so its index cannot be reused by the new one), that value needs no
    gradient (these were computed without one), and no frozen function is recording (its replays must read
    the texture, whose value may change between them).  Otherwise None: the caller traces them.
    """

    def __init__(self, value, derived):
        self.value = value                  # a view of the texture's value (it follows assignments)
        self.held = type(value)(value)      # the variable the values were derived from
        self.derived = derived

    def get(self):
        if (self.value.index != self.held.index or dr.grad_enabled(self.value)
                or dr.flag(dr.JitFlag.FreezingScope)):
            return None
        return self.derived


#: the instance's Python-only state, held in slots rather than in its ``__dict__``: ``dr.freeze`` walks the
#: ``__dict__`` of every live instance at every replay (~4 us per entry), to find its Dr.Jit values, which
#: live in the textures and the DHR lookup (kept in ``__dict__``)
_PYTHON_STATE = ("m_rough_key", "m_sample_visible", "m_reader", "m_g1", "m_g", "m_visible_ratio", "m_sampler",
                 "m_snapshots", "m_shadowing", "m_rough_scale", "m_rough_range", "m_rough_constant", "m_polarized",
                 "m_material", "m_gain_warned", "m_g_product", "m_diffuse_factor", "m_albedo_mean", "m_achromatic",
                 "m_rough_values", "m_has_diffuse", "m_guard_tiny", "m_guard_scale", "m_guard_index",
                 "m_guard_albedo", "m_diffuse", "m_achromatic_scale")


def _make_class():
    """Build the BSDF class for the current variant (mi.BSDF differs per variant)."""

    class HydeBSDF(mi.BSDF):
        __doc__ = DOC
        __slots__ = _PYTHON_STATE + ("__dict__",)

        def __init__(self, props):
            mi.BSDF.__init__(self, props)
            _refuse_outside_model(props)
            key, self.m_rough = _read_roughness(props)
            self.m_rough_key = key
            # alpha = sqrt(2) rms_slope: eval converts the texture's alpha into rms_slope
            self.m_rough_scale = 1.0 / SQRT2 if key == "alpha" else 1.0
            self.m_rough_range = (ALPHA if key == "alpha" else RMS_SLOPE).bounds
            self.m_eta, self.m_k, self.m_material = _read_index(props)
            self.m_specular_reflectance = props.get_texture("specular_reflectance", 1.0)
            self._texture_kinds()
            # ---- model switches (Python constants: branching on them is fine)
            shadow, term = _read_terms(props)
            self.m_shadowing, self.m_diffuse = shadow.name, term.name
            # smith without a term that reads its DHR: roughconductor's specular lobe, Mitsuba's rational G1
            fit = shadow.name == "smith" and not term.reads_dhr
            shadowing = _SHADOWING["smith_fit" if fit else shadow.name]
            self.m_g, self.m_visible_ratio, self.m_g1, self.m_sampler = shadowing
            # Smith's G is G1(wi) G1(wo) with the G1 of the density: the value and the pdf share G1(wi)
            self.m_g_product = shadow.name == "smith"
            self.m_diffuse_factor = _DIFFUSE[term.name]     # (traced, tabulated at one roughness, from the table)
            self.m_albedo = _read_albedo(props, term)
            self.m_albedo_mean = terms.PARAMETER_DEFAULTS["diffuse_reflectance"]
            self.m_has_diffuse = term.present
            self.m_snapshots, self.m_reader = {}, pc.Reader()
            # the DHR texture serves the diffuse factor and the lobe choice (p_spec)
            self.m_dhr = _dhr_lookup(shadow.name) if term.present else None
            self._validate()
            self._warn_unreadable_textures()
            self.m_sample_visible = _read_bool(props, "sample_visible", True)
            _refuse_unknown(props)
            self.m_polarized = bool(mi.is_polarized)
            self.m_components, self.m_flags = _lobe_flags(term)
            self.m_gain_warned = False
            self._warn_gain()

        def _texture_kinds(self):
            """Which textures are achromatic constants (a ``uniform`` of one number): in JIT variants those
            are read with ``eval_1`` and their terms traced on Floats, converted to a Spectrum once at the
            end (scalar variants trace nothing; there a Float is a Python double)."""
            jit = dr.is_jit_v(mi.Float)
            self.m_achromatic = jit and _achromatic(self.m_eta) and _achromatic(self.m_k)
            self.m_achromatic_scale = jit and _achromatic(self.m_specular_reflectance)

        def _index_needs_guard(self):
            """Whether eval must guard the index (|k|, a tiny or zero index): not for constants read at load
            or update (checked k >= 0) whose every value has eta or k >= INDEX_MIN, in RGB and mono
            variants (a spectrum is 0 outside its wavelengths); a dozen traced operations per call."""
            if (mi.is_spectral and not self.m_achromatic) or any(t.is_spatially_varying() for t in (self.m_eta, self.m_k)):
                return True
            values = [self.m_reader(t) for t in (self.m_eta, self.m_k)]
            if any(v is None for v in values):
                return True
            return bool(np.min(values[0]) < INDEX_MIN and np.min(values[1]) < INDEX_MIN)

        def _warn_gain(self):
            """shadowing="none": one warning per BSDF when its albedo can exceed 1 at its roughness."""
            if self.m_shadowing != "none" or self.m_gain_warned:
                return
            text = _gain_warning(self.m_rough_values, self.m_rough_scale)
            if text:
                import warnings

                warnings.warn(text, RuntimeWarning, stacklevel=4)
                self.m_gain_warned = True

        def _warn_unreadable_textures(self):
            """Textures whose values cannot be read at load are clamped at eval: one warning each; sets the
            eval-time guards of the index and of specular_reflectance."""
            lo, hi = self.m_rough_range
            _warn_unreadable(self.m_rough_key, self.m_rough, f"[{lo:.7g}, {hi:.7g}]")
            self.m_guard_index = any([_warn_unreadable(name, tex, f"[0, {ETA.hi:g}]")
                                      for name, tex in (("eta", self.m_eta), ("k", self.m_k))])
            self.m_guard_scale = _warn_unreadable("specular_reflectance", self.m_specular_reflectance, "[0, 1]")
            self.m_guard_albedo = self.m_albedo is not None and _warn_unreadable(
                "diffuse_reflectance", self.m_albedo, "[0, 1]")

        # ------------------------------------------------------------------
        # Nothing derived from the roughness is cached: alpha, the DHR texture coordinate and
        # 1 - rho_avg are computed at every call from one texture lookup, so each AD pass sees a
        # fresh graph edge from the texture's data (a copy derived once would lose its gradient
        # after the first dr.backward, which consumes the graph).
        def traverse(self, callback):
            flags = mi.ParamFlags.Differentiable | mi.ParamFlags.Discontinuous
            # the user's spelling: "alpha" holds Beckmann alpha (roughconductor's meaning)
            callback.put(self.m_rough_key, self.m_rough, flags)
            callback.put("eta", self.m_eta, flags)
            callback.put("k", self.m_k, flags)
            callback.put("specular_reflectance", self.m_specular_reflectance, +mi.ParamFlags.Differentiable)
            if self.m_albedo is not None:
                callback.put("diffuse_reflectance", self.m_albedo, +mi.ParamFlags.Differentiable)

        def parameters_changed(self, keys=[]):
            """Validate updated values exactly as the constructor does (ValueError naming the key).

            Only the textures named in ``keys`` are checked: ``params.update()`` passes the names
            of the children whose values changed (e.g. ``["alpha"]``; eta and k are checked
            together), so an optimisation loop pays for the check of what it changes, once per
            update (a readable texture: one small kernel and a read-back).  No ``keys``: all.
            Inside a ``dr.freeze`` recording values cannot be read back: the checks are skipped
            there (call ``params.update()`` outside the frozen function to keep them).
            """
            if dr.flag(dr.JitFlag.FreezingScope):
                return
            names = self._changed(keys)
            try:
                self._validate(names)
                if self.m_rough_key in names:
                    self._warn_gain()
            except ValueError:
                # atomic update: a refused value leaves the BSDF as it was before the call
                for group in self._groups(names):
                    self.m_snapshots[group].restore()
                self.m_reader.clear()
                raise

        def replace_texture(self, name, texture):
            """Put ``texture`` in place of the texture of traverse name ``name`` (``alpha`` or
            ``rms_slope``, ``eta``, ``k``, ``specular_reflectance``) and check it as an update would
            (a refused one is not kept).  Used to swap a bitmap for one with another ``filter_type``
            (:func:`hyde_bsdf.render.texture_filter.bitmap_to_nearest`); call ``mi.traverse`` again
            afterwards (the old texture's parameters no longer reach the BSDF)."""
            attrs = {self.m_rough_key: "m_rough", "eta": "m_eta", "k": "m_k",
                     "specular_reflectance": "m_specular_reflectance"}
            if self.m_albedo is not None:
                attrs["diffuse_reflectance"] = "m_albedo"
            if name not in attrs:
                raise UsageError(f"hyde: replace_texture: unknown parameter {shorten(name)}; use {', '.join(attrs)}")
            old = getattr(self, attrs[name])
            setattr(self, attrs[name], texture)
            self.m_reader.clear()           # nothing of the old texture is kept
            self._texture_kinds()
            try:
                self._validate((name,))
            except ValueError:
                setattr(self, attrs[name], old)
                self._texture_kinds()
                self._validate((name,))
                raise

        def _textures(self):
            """{traverse name: texture} of the checked parameters."""
            out = {self.m_rough_key: self.m_rough, "eta": self.m_eta, "k": self.m_k,
                   "specular_reflectance": self.m_specular_reflectance}
            if self.m_albedo is not None:
                out["diffuse_reflectance"] = self.m_albedo
            return out

        def _changed(self, keys):
            """The changed traverse names among ``keys`` (``alpha`` or ``alpha.data``); all without keys."""
            names = {str(key).split(".")[0] for key in (keys or [])}
            return tuple(names) if names and names <= set(self._textures()) else tuple(self._textures())

        def _groups(self, names):
            """{check group: its textures} of the groups the names belong to: the roughness, the index
            (eta and k: checked together, they must not both be 0), specular_reflectance."""
            groups = {"rough": [self.m_rough], "index": [self.m_eta, self.m_k],
                      "scale": [self.m_specular_reflectance], "albedo": [self.m_albedo]}
            of = {self.m_rough_key: "rough", "eta": "index", "k": "index", "specular_reflectance": "scale",
                  "diffuse_reflectance": "albedo"}
            return {g: groups[g] for g in dict.fromkeys(of[n] for n in names)}

        def _validate(self, names=None):
            """The checks of :mod:`hyde_bsdf.mitsuba.param_checks` of the named parameters (default
            all); on success their values are kept as the state a refused update returns to."""
            textures = self._textures()
            names = tuple(textures) if names is None else names
            for name in names:              # changed: read them again
                self.m_reader.forget(textures[name])
            groups = self._groups(names)
            if "rough" in groups:
                self.m_rough_values = pc.check_roughness(self.m_rough_key, self.m_rough, self.m_rough_scale,
                                                         self.m_reader)
                self.m_rough_constant = self._rough_constant()
            if "index" in groups:
                pc.check_index(self.m_eta, self.m_k, self.m_reader)
                self.m_guard_tiny = self._index_needs_guard()
            if "scale" in groups:
                pc.check_reflectance(self.m_specular_reflectance, self.m_reader)
            if "albedo" in groups:      # its mean chooses the lobe to sample (p_spec); unreadable: the default
                mean = pc.check_reflectance(self.m_albedo, self.m_reader, "diffuse_reflectance", DIFFUSE_REFLECTANCE.hi)
                self.m_albedo_mean = terms.PARAMETER_DEFAULTS["diffuse_reflectance"] if mean is None else mean
            for group, members in groups.items():
                self.m_snapshots[group] = pc.Snapshot(members, self.m_reader)

        def to_string(self):
            index = (f"material={self.m_material!r}" if self.m_material else
                     f"eta={self.m_eta}, k={self.m_k}")
            return (f"HydeBSDF[{self.m_rough_key}={_describe(self.m_rough)}, {index}, "
                    f"specular_reflectance={self.m_specular_reflectance}, "
                    + (f"diffuse_reflectance={self.m_albedo}, " if self.m_albedo is not None else "") +
                    f"shadowing={self.m_shadowing!r}, "
                    f"diffuse={self.m_diffuse!r}, sample_visible={self.m_sample_visible}]")

        # ------------------------------------------------------------------
        def _rough(self, si, active):
            """Roughness at the shading point: one texture lookup per call, shared by all terms.

            Returns (alpha, rms_slope, u, 1 - rho_avg, table): an ``alpha`` texture's value is used as the
            Beckmann alpha unchanged (bit-identical to roughconductor's), rms_slope = alpha / sqrt(2); u
            is the DHR texture's slope coordinate and 1 - rho_avg its 1-D lookup, read once per call for
            the lobe choice and the reciprocal term (both None without a diffuse term).  A constant roughness's
            are computed once per value (:meth:`_rough_constant`), not traced at every call, and so is its
            table of the diffuse factor over the polar angle (an ``optics.DHRSlice``; else None).
            """
            if self.m_rough_constant is not None:
                derived = self.m_rough_constant.get()
                if derived is not None:
                    return derived
            return self._rough_traced(si, active)

        def _rough_constant(self):
            """The values of :meth:`_rough` of a constant roughness (a ``uniform`` texture of one number whose
            value needs no gradient), traced here once, at load and at each update (a :class:`_Derived`), else
            None.  They are not evaluated here (that would compile a kernel at load): Dr.Jit computes them inside
            the render's kernel, from operations traced once instead of at every call."""
            if not dr.is_jit_v(mi.Float):
                return None
            params = self.m_reader.traverse(self.m_rough)
            if not _achromatic(self.m_rough, params):
                return None
            value = params["value"]
            if dr.grad_enabled(value):
                return None
            derived = self._rough_traced(dr.zeros(mi.SurfaceInteraction3f), True)
            if self.m_dhr is not None and self.m_diffuse_factor is not None and self.m_rough_values is not None:
                # the diffuse factor over the polar angle at this roughness: one 1-D lookup per direction
                lo, hi = self.m_rough_range
                r = min(max(float(np.max(self.m_rough_values)), lo), hi)
                one_minus, one_minus_avg = self.m_dhr.column(r * self.m_rough_scale)
                derived = derived[:4] + (po.DHRSlice(self.m_diffuse_factor[1](one_minus, one_minus_avg)),)
            return _Derived(value, derived)

        def _rough_traced(self, si, active):
            """:meth:`_rough` from one texture lookup."""
            r = self.m_rough.eval_1(si, active)
            # values were range-checked at load/update where readable (mesh attributes are not);
            # values below the lower bound (alpha = 0: a mirror) are floored there, and NaN too
            # (the comparison is false for NaN)
            lo, hi = self.m_rough_range
            r = dr.minimum(dr.select(r >= lo, r, lo), hi)
            if self.m_rough_key == "alpha":
                alpha, rms = r, r * (1.0 / SQRT2)
            else:
                alpha, rms = SQRT2 * r, r
            if self.m_dhr is None:
                return alpha, rms, None, None, None
            u = self.m_dhr.slope_coord(rms)
            return alpha, rms, u, self.m_dhr.one_minus_rho_avg(u), None

        def _scale(self, si, active):
            """specular_reflectance; values not readable at load are clamped to [0, 1] (NaN: 0)."""
            scale = (self.m_specular_reflectance.eval_1(si, active) if self.m_achromatic_scale
                     else self.m_specular_reflectance.eval(si, active))
            if self.m_guard_scale:
                scale = dr.select(scale >= 0, dr.minimum(scale, 1.0), 0.0)
            return scale

        def _distr(self, rough):
            return mi.MicrofacetDistribution(mi.MicrofacetType.Beckmann, rough[0], self.m_sample_visible)

        def _index(self, si, active):
            """(n, k): Floats for achromatic constants (``m_achromatic``), else spectra."""
            if self.m_achromatic:
                n, k = self.m_eta.eval_1(si, active), self.m_k.eval_1(si, active)
            else:
                n, k = self.m_eta.eval(si, active), self.m_k.eval(si, active)
            if not self.m_guard_tiny:      # constants checked at load/update: k >= 0, eta or k >= INDEX_MIN
                return n, k
            # Mitsuba's polarized Fresnel uses |k| (it conjugates n + ik into n - ik)
            k = dr.abs(k)
            # a spectrum is 0 outside its wavelength range: index 0 would give 0/0 at normal
            # incidence; take it as 1 there (no interface, no reflection).  A tiny nonzero index
            # (|eta| < 1e-6, eta^2 underflows) is floored at n = 1e-6: the mirror limit of eta -> 0
            tiny = (n < INDEX_MIN) & (k < INDEX_MIN)
            n = dr.select(tiny, dr.select((n == 0) & (k == 0), 1.0, INDEX_MIN), n)
            if self.m_guard_index:
                # values not readable at load: clamped to [0, ETA.hi]; NaN -> index 1 (no reflection)
                bad = dr.isnan(n) | dr.isnan(k)
                n = dr.select(bad, 1.0, dr.clip(n, 0.0, ETA.hi))
                k = dr.select(bad, 0.0, dr.minimum(k, ETA.hi))
            return n, k

        @staticmethod
        def _half_vector(wi, wo):
            """(h, found): the facet normal h = normalize(wi + wo), and where it is found.

            Named fallback, "opposite": |wi + wo| < MIN_HALF (wi = -wo to float32 precision; above the surface
            only where both lie within 1e-15 of the horizon) has no half vector: the pair reflects nothing
            (``found`` is false; h is then finite and unused).  Elsewhere the squared norm, >= MIN_HALF^2 =
            1e-30, neither underflows nor loses a component (squares down to 2^-24 of it are normal floats).
            """
            v = wi + wo
            n2 = dr.squared_norm(v)
            found = n2 >= MIN_HALF * MIN_HALF
            return v * dr.rsqrt(dr.select(found, n2, 1.0)), found

        def _geometry(self, wi, wo, active):
            """(active, cos_i, cos_o, h, wi.h) of a direction pair: shared by the value and the pdf.  Where both
            directions are above the surface (``active``), wi.h = wo.h = |wi + wo| / 2 > 0: both see the facet's
            front, and no other check of it is needed."""
            cos_i = mi.Frame3f.cos_theta(wi)
            cos_o = mi.Frame3f.cos_theta(wo)
            h, found = self._half_vector(wi, wo)
            return active & (cos_i > 0) & (cos_o > 0) & found, cos_i, cos_o, h, dr.dot(wi, h)

        def _diffuse(self, ctx, cos_i, cos_o, rough):
            """The diffuse term's factor (no M00, no cos theta_o); theta_in is the polar angle of the
            direction the light arrives from (wo_hat: ``wo`` in Radiance mode, ``si.wi`` in Importance)."""
            cos_in = cos_o if ctx.mode == mi.TransportMode.Radiance else cos_i
            traced, _, from_table = self.m_diffuse_factor
            if rough[4] is not None:        # a constant roughness: its 1-D table
                return from_table(rough[4], cos_in, cos_i, cos_o)
            return traced(self.m_dhr, cos_in, cos_i, cos_o, rough[2], rough[3])

        def _lobes(self, ctx):
            """(specular on, diffuse on) for this context (Python booleans)."""
            return (ctx.is_enabled(mi.BSDFFlags.GlossyReflection, 0),
                    self.m_has_diffuse and ctx.is_enabled(mi.BSDFFlags.DiffuseReflection, 1))

        def _p_spec(self, lobes, rough):
            """Probability of sampling the specular lobe (a Python constant or a Float)."""
            spec_on, diff_on = lobes
            if spec_on and not diff_on:
                return 1.0
            if diff_on and not spec_on:
                return 0.0
            if not (spec_on or diff_on):
                return None
            # ratio of the lobe albedos rho F : (1 - rho) F (F common to both), with rho averaged
            # over the incidence angle: a 1-D lookup (4.6 kB, in cache) in place of a 2-D one into the
            # 4.7 MB texture, which with the diffuse factor's own lookup slowed the default model's
            # kernels (benchmarks/bench_render.py measures the ratio).  Any p_spec in (0, 1) is unbiased (the
            # same p_spec is in the sampled pdf); this one only gives less variance-optimal
            # choices near grazing incidence, where rho departs from its average
            rho_avg = 1.0 - rough[3]
            if self.m_albedo is not None:
                # the Lambertian term: specular albedo rho_avg F against its own, the albedo's mean
                # (a constant of the texture: no gradient flows through the choice of lobe)
                return dr.clip(rho_avg / (rho_avg + self.m_albedo_mean + 1e-6), 0.05, 0.95)
            return dr.clip(rho_avg, 0.05, 0.95)

        def _lobe(self, distr, wi, wo, h, cos_i, value, pdf):
            """(D G / (4 cos theta_i), its sampling density): the specular lobe of paper Eq. 13 without M and
            times cos theta_o, and the density the sampler draws h from (visible normals: D G1(wi) / (4 cos
            theta_i); else D cos theta_h / (4 wo.h)), each capped at MAX_LOBE, None where not asked for.

            D(h), G1(wi) (a factor of both with Smith shadowing) and 4 cos theta_i are traced once for the two.
            """
            d = distr.eval(h)
            four_cos_i = 4.0 * _pos(cos_i)
            g1_i = self.m_g1(distr, wi, h) if self.m_g_product or (pdf and self.m_sample_visible) else None
            lobe = density = None
            if value:
                g = g1_i * self.m_g1(distr, wo, h) if self.m_g_product else self.m_g(distr, wi, wo, h)
                lobe = dr.minimum(d * g / four_cos_i, MAX_LOBE)
            if pdf:
                if self.m_sample_visible:
                    density = d * g1_i / four_cos_i
                else:
                    density = distr.pdf(po.snap_to_normal(wi), h) / (4.0 * _pos(dr.dot(wo, h)))
                density = dr.minimum(density, MAX_LOBE)
            return lobe, density

        def _mueller(self, ctx, si, wo, cos_beta, n, k, spec, diff, scale, active):
            """(Fresnel(beta) spec + M00(beta) diff) scale as a Spectrum (Mueller matrix if polarized), 0
            where not ``active``; ``cos_beta`` = wi.h, the facet's incidence cosine.

            ``spec`` (a Float) multiplies the facet Fresnel Mueller matrix (paper Eq. 11) rotated
            into Mitsuba's Stokes bases; ``diff`` (a Float or 0.0) multiplies only its unpolarized
            M00 and goes into the [0, 0] element (the diffuse term of Eq. 17); ``scale`` is
            specular_reflectance.  Inactive lanes are masked on Floats (the lobe factors, cos beta
            and the basis rotations), not on the 16 spectral entries: the Fresnel terms are
            evaluated at cos beta = 1 there (finite), times factors that are 0.
            """
            no_diff = isinstance(diff, float) and diff == 0.0
            # a Float: broadcast to the index's spectrum where needed
            cos_beta = dr.select(active, cos_beta, 1.0)
            if not self.m_polarized:    # both terms multiply the same Fresnel average: their sum, masked once
                weight = dr.select(active, spec if no_diff else spec + diff, 0.0) * scale
                if isinstance(n, mi.Float):
                    fresnel = po.fresnel_average(cos_beta, n, k)
                else:   # per channel on Floats: ~2x fewer host microseconds than on the spectrum type
                    fresnel = type(n)(*[po.fresnel_average(cos_beta, n[i], k[i]) for i in range(len(n))])
                value = fresnel * weight
                return value if isinstance(value, mi.Spectrum) else mi.Spectrum(value)
            spec = dr.select(active, spec, 0.0) * scale
            if not no_diff:
                diff = dr.select(active, diff, 0.0) * scale
            a, b, c, s = po.fresnel_mueller_entries(*po.facet_fresnel(cos_beta, n, k))
            # Light arrives along -wo_hat and leaves along +wi_hat (roughconductor's frames)
            if ctx.mode == mi.TransportMode.Radiance:
                wo_hat, wi_hat = wo, si.wi
            else:
                wo_hat, wi_hat = si.wi, wo
            # The facet's s axis is perpendicular to its plane of incidence: roughconductor
            # uses h x (-wo_hat) = h x wi_hat, both parallel to wo_hat x wi_hat, which is
            # computed here with a compensated cross product (accurate near backscatter).
            # Named fallback, "collinear": wo_hat and wi_hat parallel to float32 precision
            # (backscatter, or both along the normal; |wo_hat x wi_hat| < 1e-37).  The facet is
            # then seen at normal incidence, where its Mueller matrix is invariant under a
            # rotation of the s axis, so any axis perpendicular to both directions is exact:
            # stokes_basis(-wo_hat) (which makes the input rotation the identity).
            basis_in = mi.mueller.stokes_basis(-wo_hat)
            s_axis = po.safe_normalize(po.accurate_cross(wo_hat, wi_hat), basis_in)
            # the facet matrix rotated from (s_axis, s_axis) into (stokes_basis(-wo_hat),
            # stokes_basis(wi_hat)): mi.mueller.rotate_mueller_basis written out (stokes.py)
            rot_in = ps.stokes_rotation(-wo_hat, s_axis, basis_in)
            rot_out = ps.stokes_rotation(wi_hat, s_axis, mi.mueller.stokes_basis(wi_hat))
            return ps.rotated_facet_mueller(a, b, c, s, [dr.select(active, x, 0.0) for x in rot_in],
                                            [dr.select(active, x, 0.0) for x in rot_out], spec, diff)

        def _value(self, ctx, si, wo, geo, rough, lobes, lobe, inv_pdf=None):
            """f cos(theta_o) as a Spectrum (Mueller matrix in polarized variants), ``lobe`` the specular
            D G / (4 cos theta_i) of :meth:`_lobe`; with ``inv_pdf`` (a Float, 0 where the sample failed) the
            sampling weight f cos(theta_o) / pdf."""
            spec_on, diff_on = lobes
            if not (spec_on or diff_on):
                return dr.zeros(mi.Spectrum)
            active, cos_i, cos_o, h, wi_h = geo
            n, k = self._index(si, active)
            scale = self._scale(si, active)
            spec = lobe if spec_on else 0.0
            paper = diff_on and self.m_diffuse_factor is not None
            diff = self._diffuse(ctx, cos_i, cos_o, rough) * cos_o if paper else 0.0
            lambertian = diff_on and self.m_albedo is not None
            weight = cos_o * dr.inv_pi if lambertian else None
            if inv_pdf is not None:     # scaled here: a division of the whole Mueller matrix is slow to trace
                spec, diff = spec * inv_pdf, (diff * inv_pdf if paper else 0.0)
                weight = weight * inv_pdf if lambertian else None
                active = active & (inv_pdf > 0)
            value = self._mueller(ctx, si, wo, wi_h, n, k, spec, diff, scale, active)
            if lambertian:
                value = value + self._lambertian(si, dr.select(active, weight, 0.0), active)
            return value

        def _lambertian(self, si, weight, active):
            """The Lambertian term, diffuse_reflectance / pi times ``weight`` (cos theta_o, over the pdf when
            sampling): unpolarized, a depolarizer in the [0, 0] element (the same in both transport modes)."""
            albedo = self.m_albedo.eval(si, active)
            if self.m_guard_albedo:
                albedo = dr.select(albedo >= 0, dr.minimum(albedo, 1.0), 0.0)
            value = albedo * weight
            return mi.depolarizer(value) if self.m_polarized else value

        def _pdf(self, wo, geo, p_spec, density):
            """The mixture density of :meth:`sample` (``p_spec`` from :meth:`_p_spec`, ``density`` the
            specular lobe's from :meth:`_lobe`)."""
            if p_spec is None:
                return mi.Float(0.0)
            active, cos_i, cos_o, h, wi_h = geo
            pdf_spec = 0.0
            if not (isinstance(p_spec, float) and p_spec == 0.0):
                # 0 where not active; active: wi.h = wo.h > 0 (``_geometry``)
                if isinstance(p_spec, float) and p_spec == 1.0:
                    return dr.select(active, density, 0.0)
                pdf_spec = density      # masked with the mixture below
            pdf_diff = mi.warp.square_to_cosine_hemisphere_pdf(wo)
            return dr.select(active, p_spec * pdf_spec + (1.0 - p_spec) * pdf_diff, 0.0)

        def _specular_wanted(self, lobes, p_spec, value, pdf):
            """(the lobe's value wanted, its density wanted): not when the lobe is off or never sampled."""
            return (value and lobes[0], pdf and p_spec is not None and not (isinstance(p_spec, float) and p_spec == 0.0))

        # ------------------------------------------------------------------
        # eval, pdf, eval_pdf and sample share one roughness lookup, one geometry, one distribution and
        # the specular lobe's factors per call: each is traced on the host for every live instance at
        # every render (the cost per instance: benchmarks/bench_render.py --instances)
        def _eval_pdf(self, ctx, si, wo, active, value, pdf):
            lobes = self._lobes(ctx)
            rough = self._rough(si, active)
            wi = si.wi
            geo = self._geometry(wi, wo, active)
            p_spec = self._p_spec(lobes, rough) if pdf else None
            want_value, want_pdf = self._specular_wanted(lobes, p_spec, value, pdf)
            lobe, density = (self._lobe(self._distr(rough), wi, wo, geo[3], geo[1], want_value, want_pdf)
                             if want_value or want_pdf else (None, None))
            return (self._value(ctx, si, wo, geo, rough, lobes, lobe) if value else None,
                    self._pdf(wo, geo, p_spec, density) if pdf else None)

        def eval(self, ctx, si, wo, active=True):
            return self._eval_pdf(ctx, si, wo, active, True, False)[0]

        def pdf(self, ctx, si, wo, active=True):
            return self._eval_pdf(ctx, si, wo, active, False, True)[1]

        def eval_pdf(self, ctx, si, wo, active=True):
            return self._eval_pdf(ctx, si, wo, active, True, True)

        def _sample_normal(self, distr, wi, sample2, u):
            """(m, its density) from the visible normals of the shadowing (``m_sampler``), else D cos theta_m."""
            return (self.m_sampler if self.m_sample_visible else _sample_smith)(distr, wi, sample2, u)

        def _sample_specular(self, ctx, si, wi, sample1, sample2, active, distr):
            """The specular lobe alone (p_spec = 1): with Smith shadowing exactly roughconductor's sampling routine."""
            bs = dr.zeros(mi.BSDFSample3f)
            m, pdf = self._sample_normal(distr, wi, sample2, sample1)
            wo = bs.wo = mi.reflect(wi, m)
            bs.eta = 1.0
            bs.sampled_component = mi.UInt32(0)
            bs.sampled_type = mi.UInt32(+mi.BSDFFlags.GlossyReflection)
            active = active & (pdf != 0) & (mi.Frame3f.cos_theta(wo) > 0)
            if self.m_sample_visible and self.m_g1 is _g1_exact:
                # the visible-normal density the sampler draws from: D G1_exact(wi) / (4 cos_i) (wi.m = wo.m);
                # distr.sample's own pdf is written with the rational G1 (roughconductor's)
                bs.pdf = dr.minimum(distr.eval(m) * self.m_g1(distr, wi, m) / (4.0 * _pos(mi.Frame3f.cos_theta(wi))),
                                    MAX_LOBE)
            else:
                bs.pdf = pdf / (4.0 * _pos(dr.dot(wo, m)))
            # weight = f cos_o / pdf, written with the sampled m like roughconductor
            wi_m = dr.dot(wi, m)
            if self.m_sample_visible and self.m_visible_ratio is not None:
                g_ratio = self.m_visible_ratio(distr, wi, wo, m)
            elif self.m_sample_visible:
                g_ratio = self.m_g(distr, wi, wo, m) / _pos(self.m_g1(distr, wi, m))
            else:
                g_ratio = (self.m_g(distr, wi, wo, m) * wi_m
                           / _pos(mi.Frame3f.cos_theta(wi) * mi.Frame3f.cos_theta(m)))
            n, k = self._index(si, active)
            bs.pdf = dr.select(active, bs.pdf, 0.0)
            return bs, self._mueller(ctx, si, wo, wi_m, n, k, g_ratio, 0.0, self._scale(si, active), active)

        def sample(self, ctx, si, sample1, sample2, active=True):
            wi = si.wi
            active = active & (mi.Frame3f.cos_theta(wi) > 0)
            lobes = self._lobes(ctx)
            rough = self._rough(si, active)
            p_spec = self._p_spec(lobes, rough)
            if p_spec is None:
                return dr.zeros(mi.BSDFSample3f), dr.zeros(mi.Spectrum)
            distr = self._distr(rough)
            if isinstance(p_spec, float) and p_spec == 1.0:
                return self._sample_specular(ctx, si, wi, sample1, sample2, active, distr)

            # mixture of the specular (glossy) and diffuse lobes
            bs = dr.zeros(mi.BSDFSample3f)
            choose_spec = sample1 < p_spec
            m, pdf_m = self._sample_normal(distr, wi, sample2, sample1 / p_spec)   # on the lanes that use m: in [0, 1)
            # a back-facing normal (possible without visible-normal sampling) is a failed sample
            # (sample1 >= p_spec), not ~choose_spec: in scalar variants choose_spec is a Python bool
            drawn = (pdf_m != 0) if self.m_sample_visible else (pdf_m != 0) & (dr.dot(wi, m) > 0)
            active = active & ((sample1 >= p_spec) | drawn)
            wo_spec = mi.reflect(wi, m)
            wo_diff = mi.warp.square_to_cosine_hemisphere(sample2)
            wo = bs.wo = dr.select(choose_spec, wo_spec, wo_diff)
            bs.eta = 1.0
            bs.sampled_component = dr.select(choose_spec, mi.UInt32(0), mi.UInt32(1))
            bs.sampled_type = dr.select(choose_spec, mi.UInt32(+mi.BSDFFlags.GlossyReflection),
                                        mi.UInt32(+mi.BSDFFlags.DiffuseReflection))
            active = active & (mi.Frame3f.cos_theta(wo) > 0)
            geo = self._geometry(wi, wo, active)
            want_value, want_pdf = self._specular_wanted(lobes, p_spec, True, True)
            lobe, density = (self._lobe(distr, wi, wo, geo[3], geo[1], want_value, want_pdf)
                             if want_value or want_pdf else (None, None))
            pdf = self._pdf(wo, geo, p_spec, density)
            ok = active & (pdf > 0)
            bs.pdf = dr.select(ok, pdf, 0.0)
            inv_pdf = dr.select(ok, dr.rcp(dr.select(ok, pdf, 1.0)), 0.0)
            return bs, self._value(ctx, si, wo, geo, rough, lobes, lobe, inv_pdf)
    HydeBSDF.__name__ = "HydeBSDF"
    return HydeBSDF


_CLASSES: dict = {}
#: variants in which ``hyde`` is registered in this process (a repeated ``register()`` skips them)
_REGISTERED: set = set()
#: held while a variant's class is built (Mitsuba may load two ``hyde`` BSDFs of a scene at once)
_BUILD = threading.Lock()


def plugin_class():
    """The HydeBSDF class for the current Mitsuba variant (built once per variant)."""
    variant = mi.variant()
    if variant is None:
        raise RuntimeError("hyde: call mi.set_variant(...) before using the hyde plugin")
    with _BUILD:
        if variant not in _CLASSES:
            _CLASSES[variant] = _make_class()
    return _CLASSES[variant]


def _construct(variant: str, props):
    """Mitsuba's constructor of ``hyde`` in ``variant``.  The variant's class is built at the first ``hyde``
    loaded there (:func:`plugin_class`), when that variant is the selected one, not at registration."""
    if variant not in _CLASSES and mi.variant() != variant:
        raise RuntimeError(f"hyde: a {variant!r} scene is loaded while {mi.variant()!r} is selected; "
                           f"call mi.set_variant({variant!r}) first")
    return (_CLASSES[variant] if variant in _CLASSES else plugin_class())(props)


def register(variant: str | None = None) -> list[str]:
    """Register the ``hyde`` BSDF with Mitsuba; returns the variants it was registered in.

    Registration is per variant in Mitsuba.  With no argument ``hyde`` is registered in
    every variant usable here (:func:`hyde_bsdf.mitsuba.variants.usable_variants`: the
    ``llvm_*`` ones only with a libLLVM >= 16, the ``cuda_*`` ones only with a CUDA
    device), so a later ``mi.set_variant`` of any of them finds it.  With a variant name,
    only that one; an unusable one raises
    :class:`hyde_bsdf.mitsuba.variants.VariantUnavailable` (a ``RuntimeError``) that says
    which variant to use instead.  The selected variant is not changed (if none was set, the
    last registered one is selected: call ``mi.set_variant`` before use).  Calling it
    again is harmless.

    Each variant's Mitsuba module takes the registration directly (``mitsuba.llvm_ad_rgb.register_bsdf``),
    without selecting the variant: selecting one costs ~0.2 CPU s (Mitsuba re-imports its Python AD
    integrators), so registering in all eight usable variants by switching through them cost ~1.8 CPU s,
    most of a validation script's start.  The plugin's class is built per variant at its first use.
    """
    import importlib

    from hyde_bsdf.mitsuba.variants import VariantUnavailable, _cpu_twin, usable_variant, usable_variants

    if variant is None:
        targets = usable_variants()
    else:
        usable_variant(variant, fallback=False)   # raises, naming the alternative, if unusable
        targets = [variant]
    done = []
    for v in targets:
        if v not in _REGISTERED:        # Mitsuba keeps a registration for the process
            try:
                module = importlib.import_module(f"mitsuba.{v}")
            except ImportError as exc:   # a CUDA device present but not usable
                if variant is not None:
                    raise VariantUnavailable(f"variant={v!r} cannot be initialised here ({exc}); "
                                             f"use {_cpu_twin(v)!r} instead") from exc
                continue
            module.register_bsdf("hyde", lambda props, v=v: _construct(v, props))
            _REGISTERED.add(v)
        done.append(v)
    if done and mi.variant() is None:
        mi.set_variant(done[-1])
    return done
