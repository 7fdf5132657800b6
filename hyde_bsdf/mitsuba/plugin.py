"""The ``hyde`` BSDF: Hyde-Schmidt-Havrilla (2009) pBRDF as a Mitsuba 3 plugin.

Call :func:`register` (also exposed as ``hyde_bsdf.register()``) after
``mi.set_variant``; then ``{'type': 'hyde', ...}`` / ``<bsdf type="hyde">``
works in that variant.  The parameter table and the conventions are in
:data:`DOC` (which is also the class docstring).
"""
from __future__ import annotations

import math
import os

import drjit as dr
import mitsuba as mi

from hyde_bsdf.mitsuba import optics as po

__all__ = ["register", "plugin_class", "DOC", "SHADOWING", "DIFFUSE"]

SHADOWING = ("vgroove", "smith", "none")
DIFFUSE = ("paper", "reciprocal", "none")
SQRT2 = math.sqrt(2.0)

DOC = r"""Hyde-Schmidt-Havrilla polarimetric rough-surface BRDF (``hyde``).

.. list-table::
   :header-rows: 1

 * - Parameter
   - Type
   - Default
   - Meaning
   - Exposed / differentiable
 * - rms_slope
   - float
   - 0.3 (if no roughness is given)
   - the paper's roughness sqrt(2) sigma_h / ell (rms facet slope along one axis);
     useful range 0.02-1.5; accepted (0, 50], [0.01, 3] with a diffuse term
   - exposed as ``rms_slope``, differentiable, discontinuous
 * - alpha
   - float
   - (none)
   - Beckmann alpha = sqrt(2) rms_slope = 2 sigma_h / ell (Mitsuba's roughconductor alpha);
     alternative to rms_slope
   - (stored as rms_slope)
 * - sigma_h, ell
   - float, float
   - (none)
   - rms surface height and Gaussian correlation length (same units, both needed);
     alternative to rms_slope
   - (stored as rms_slope)
 * - eta, k
   - float or spectrum texture
   - 0, 1 (a 100 % reflective mirror, as roughconductor)
   - real and imaginary part of the complex index n + i k (Mitsuba's sign;
     the paper writes the same material as eta = n - j kappa); k >= 0
   - exposed as ``eta.value``, ``k.value``, differentiable, discontinuous
 * - material
   - string
   - (none)
   - a named metal from Mitsuba's ``data/ior`` tables ("Au", "Al", "Cu", "Ag", ...);
     alternative to eta/k.  RGB variants convert the spectra to unbounded sRGB and
     mono variants to luminance, as Mitsuba's own conductors do
   - as eta, k
 * - shadowing
   - string
   - "vgroove"
   - shadowing/masking G: "vgroove" (paper Eq. 12, Torrance-Sparrow/Blinn),
     "smith" (Beckmann Smith G1 product with Mitsuba's rational approximation,
     as roughconductor), "none" (G = 1)
   - no
 * - diffuse
   - string
   - "paper"
   - the unpolarized diffuse term: "paper" = Eq. 17, (1/pi) (1 - rho(theta_in)) M00(beta);
     "reciprocal" = (1 - rho(theta_i))(1 - rho(theta_o)) M00(beta) / (pi (1 - rho_avg));
     "none" = specular lobe only
   - no
 * - sample_visible
   - bool
   - true
   - sample the specular lobe from the visible Beckmann normals (Heitz & d'Eon 2014)
   - no

Model.  f = D(h) M(beta; eta) G / (4 cos theta_i cos theta_o)  +  diffuse (paper
Eqs. 6, 8, 11, 12, 13, 17), where D is the Beckmann distribution with
alpha = sqrt(2) rms_slope (identical to the paper's Eq. 8 divided by cos alpha),
h = normalize(wi + wo) the facet normal, cos beta = wi.h, and M the facet Fresnel
Mueller matrix rotated from the facet s/p bases into Mitsuba's Stokes bases.
``eval`` returns f cos(theta_o) (Mitsuba's convention); the BSDF is one-sided.
rho = rho^{s,PEC}(theta, rms_slope) is the directional-hemispherical reflectance
of the specular lobe of a perfect conductor (Eqs. 14-16) for the chosen
shadowing, read from :func:`hyde_bsdf.model.dhr.load_table` through a Dr.Jit texture.

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
:mod:`hyde_bsdf.mitsuba.frames`) reproduces all 16 elements of
:func:`hyde_bsdf.pbrdf`, S3 rows and columns included - no sign conversion is
needed at this boundary.  At normal incidence r_p = -r_s (Mitsuba's Fresnel
signs), so a mirror gives F00 diag(1, 1, -1, -1) in the paper's bases.

Facet frame.  The facet's s axis (perpendicular to its plane of incidence) is
wo_hat x wi_hat, parallel to roughconductor's cross(h, -wo_hat), but computed with
a compensated (Kahan) cross product: near backscatter the plain float32 product
tilts the Stokes frame by ~eps/|wi x wo| (roughconductor is off the float64
evaluator by up to 3e-5 there, this plugin by < 2e-6).  Directions collinear
with the facet normal fall back to the x axis, as in roughconductor.

Index.  Textures of eta and k are evaluated per wavelength (spectral), per RGB
channel (unbounded sRGB) or as luminance (mono); like Mitsuba, |k| is used.

DHR lookup.  1 - rho^{s,PEC} is resampled from the table's bicubic ``__call__``
onto 2049 nodes in x = 1 - sqrt(cos theta) times 640 per decade of rms_slope over
[0.01, 3] and read with a linear ``mi.Texture2f`` (differentiable in rms_slope);
its deviation from the evaluator's lookup is < 3e-6 absolute for theta <= 89 deg,
two orders below the table's own quadrature accuracy.  With a diffuse term
rms_slope must lie in [0.01, 3]; 1 - rho is clipped at 0 (rho > 1 happens
without shadowing near grazing).

Sampling.  With probability p_spec the specular lobe is sampled from the
(visible) Beckmann normals (``mi.MicrofacetDistribution``), otherwise a cosine
hemisphere.  p_spec = clamp(rho(theta(si.wi)), 0.05, 0.95): the ratio of the
specular albedo rho F to rho F + (1 - rho) F, the Fresnel factor F being common
to both lobes; p_spec = 1 when ``diffuse="none"`` (then ``sample`` equals
roughconductor's).  ``pdf`` and ``eval_pdf`` return the mixture density.

Components: 0 = glossy reflection (specular lobe), 1 = diffuse reflection.
"""


def _read_float(props, name):
    value = props.get(name)
    try:
        value = float(value)
    except (TypeError, ValueError):
        raise ValueError(f"hyde: parameter '{name}' must be a number, got {value!r}") from None
    if not math.isfinite(value):
        raise ValueError(f"hyde: parameter '{name}' must be finite, got {value!r}")
    return value


def _ior_texture(path):
    """A texture holding the spectrum in a Mitsuba ``.spd`` file, converted as ior.h does."""
    wavelengths, values = mi.spectrum_from_file(path)
    if mi.is_spectral:
        return mi.load_dict({"type": "irregular",
                             "wavelengths": ", ".join(repr(float(w)) for w in wavelengths),
                             "values": ", ".join(repr(float(v)) for v in values)})
    color = mi.spectrum_list_to_srgb(wavelengths, values, False, False)
    if mi.is_monochromatic:
        import numpy as np

        return mi.load_dict({"type": "uniform",
                             "value": float(np.asarray(mi.luminance(color), dtype=float).ravel()[0])})
    return mi.load_dict({"type": "srgb", "color": color, "unbounded": True})


def _known_materials():
    folder = os.path.join(os.path.dirname(mi.__file__), "data", "ior")
    try:
        names = sorted({f[:-len(".eta.spd")] for f in os.listdir(folder) if f.endswith(".eta.spd")})
    except OSError:
        names = []
    return names


_DHR_CACHE: dict = {}


def _dhr_lookup(shadowing):
    """One DHRLookup per (variant, shadowing), shared by all instances."""
    key = (mi.variant(), shadowing)
    if key not in _DHR_CACHE:
        from hyde_bsdf.model.dhr import load_table

        _DHR_CACHE[key] = po.DHRLookup(load_table(shadowing))
    return _DHR_CACHE[key]


_PARAMS = ("rms_slope", "alpha", "sigma_h", "ell", "eta", "k", "material",
           "shadowing", "diffuse", "sample_visible")


def _make_class():
    """Build the BSDF class for the current variant (mi.BSDF differs per variant)."""

    class HydeBSDF(mi.BSDF):
        __doc__ = DOC

        def __init__(self, props):
            mi.BSDF.__init__(self, props)

            # ---- roughness: exactly one of rms_slope / alpha / (sigma_h, ell)
            groups = [g for g, names in (("rms_slope", ("rms_slope",)), ("alpha", ("alpha",)),
                                         ("sigma_h+ell", ("sigma_h", "ell")))
                      if any(x in props for x in names)]
            if len(groups) > 1:
                raise ValueError(f"hyde: give the roughness as exactly one of rms_slope, alpha or "
                                 f"sigma_h+ell; got conflicting {', '.join(groups)}")
            if "alpha" in props:
                rms = _read_float(props, "alpha") / SQRT2
                src = "alpha"
            elif "sigma_h" in props or "ell" in props:
                missing = [x for x in ("sigma_h", "ell") if x not in props]
                if missing:
                    raise ValueError(f"hyde: sigma_h and ell must be given together; missing {missing[0]}")
                sh, ell = _read_float(props, "sigma_h"), _read_float(props, "ell")
                if sh <= 0 or ell <= 0:
                    raise ValueError(f"hyde: sigma_h and ell must be > 0, got sigma_h={sh}, ell={ell}")
                rms = SQRT2 * sh / ell
                src = "sigma_h/ell"
            else:
                rms = _read_float(props, "rms_slope") if "rms_slope" in props else 0.3
                src = "rms_slope"
            if not (0.0 < rms <= 50.0):
                raise ValueError(f"hyde: roughness from {src} gives rms_slope={rms:g}; "
                                 f"the accepted range is (0, 50]")

            # ---- index: eta/k or material
            if "material" in props:
                given = [x for x in ("eta", "k") if x in props]
                if given:
                    raise ValueError(f"hyde: give either material or eta/k, not both "
                                     f"(got material and {', '.join(given)})")
                material = str(props.get("material"))
                path = mi.file_resolver().resolve(f"data/ior/{material}.eta.spd")
                if not os.path.exists(str(path)):
                    raise ValueError(f"hyde: unknown material={material!r}; Mitsuba's data/ior has "
                                     f"{', '.join(_known_materials())}")
                self.m_eta = _ior_texture(str(path))
                self.m_k = _ior_texture(str(path).replace(".eta.spd", ".k.spd"))
                self.m_material = material
            else:
                consts = {}
                for name in ("eta", "k"):
                    if name in props and props.type(name) == mi.Properties.Type.Float:
                        consts[name] = _read_float(props, name)
                        if consts[name] < 0:
                            raise ValueError(f"hyde: parameter '{name}' must be >= 0 "
                                             f"(index n + i k with k >= 0), got {consts[name]}")
                if consts.get("eta", 0.0) == 0.0 and consts.get("k", 1.0) == 0.0:
                    raise ValueError("hyde: eta and k cannot both be 0 (no material has index 0)")
                self.m_eta = props.get_unbounded_texture("eta", 0.0)
                self.m_k = props.get_unbounded_texture("k", 1.0)
                self.m_material = None

            # ---- model switches (Python constants: branching on them is fine)
            shadowing = str(props.get("shadowing", "vgroove")).lower()
            if shadowing not in SHADOWING:
                raise ValueError(f"hyde: shadowing={shadowing!r} is not one of {', '.join(SHADOWING)}")
            diffuse = props.get("diffuse", "paper")
            if isinstance(diffuse, bool):  # <boolean name="diffuse" .../> also accepted
                diffuse = "paper" if diffuse else "none"
            diffuse = str(diffuse).lower()
            if diffuse not in DIFFUSE:
                raise ValueError(f"hyde: diffuse={diffuse!r} is not one of {', '.join(DIFFUSE)}")
            if diffuse == "reciprocal" and shadowing == "none":
                # without shadowing the specular DHR average rho_avg reaches 1: 1/(1 - rho_avg) diverges
                raise ValueError("hyde: diffuse='reciprocal' needs shadowing='vgroove' or 'smith' "
                                 "(with shadowing='none' the specular albedo average is >= 1)")
            self.m_shadowing = shadowing
            self.m_diffuse = diffuse
            self.m_sample_visible = bool(props.get("sample_visible", True))

            unknown = [x for x in props.unqueried() if x not in _PARAMS]
            if unknown:
                raise ValueError(f"hyde: unknown parameter(s) {', '.join(sorted(unknown))}; "
                                 f"accepted: {', '.join(_PARAMS)}")

            self.m_polarized = bool(mi.is_polarized)
            self.m_rms_slope = mi.Float(rms)
            self.m_dhr = _dhr_lookup(shadowing) if diffuse != "none" else None
            if self.m_dhr is not None and not (self.m_dhr.rms_lo <= rms <= self.m_dhr.rms_hi):
                raise ValueError(f"hyde: rms_slope={rms:g} is outside the DHR table range "
                                 f"[{self.m_dhr.rms_lo:g}, {self.m_dhr.rms_hi:g}] needed by "
                                 f"diffuse={diffuse!r}")

            glossy = mi.BSDFFlags.GlossyReflection | mi.BSDFFlags.FrontSide
            comps = [glossy]
            if diffuse != "none":
                comps.append(mi.BSDFFlags.DiffuseReflection | mi.BSDFFlags.FrontSide)
            self.m_components = comps
            flags = comps[0]
            for c in comps[1:]:
                flags = flags | c
            self.m_flags = flags

        # ------------------------------------------------------------------
        # Nothing derived from rms_slope is cached: alpha, the DHR texture coordinate and
        # 1 - rho_avg are recomputed at every call, so each AD pass sees a fresh graph edge
        # from rms_slope (a copy derived once would lose its gradient after the first
        # dr.backward, which consumes the graph).
        @property
        def m_alpha(self):
            return SQRT2 * self.m_rms_slope

        @property
        def m_u_slope(self):
            return self.m_dhr.slope_coord(self.m_rms_slope)

        @property
        def m_one_minus_avg(self):
            # without shadowing rho_avg can reach 1: keep the division finite
            return dr.maximum(self.m_dhr.one_minus_rho_avg(self.m_u_slope), 1e-30)

        def traverse(self, callback):
            flags = mi.ParamFlags.Differentiable | mi.ParamFlags.Discontinuous
            callback.put("rms_slope", self.m_rms_slope, flags)
            callback.put("eta", self.m_eta, flags)
            callback.put("k", self.m_k, flags)

        def parameters_changed(self, keys=[]):
            """Validate an updated rms_slope (alpha and the DHR coordinate follow it at every call).

            Outside the DHR texture's rms_slope range the diffuse term uses the
            nearest tabulated roughness (clamped texture lookup).
            """
            import numpy as np

            value = float(np.asarray(self.m_rms_slope, dtype=float).ravel()[0])
            if not (math.isfinite(value) and value > 0.0):
                raise ValueError(f"hyde: rms_slope must be a finite number > 0, got {value!r}")
            if dr.is_jit_v(type(self.m_rms_slope)):
                dr.make_opaque(self.m_rms_slope)

        def to_string(self):
            index = (f"material={self.m_material!r}" if self.m_material else
                     f"eta={self.m_eta}, k={self.m_k}")
            return (f"HydeBSDF[rms_slope={self.m_rms_slope}, {index}, shadowing={self.m_shadowing!r}, "
                    f"diffuse={self.m_diffuse!r}, sample_visible={self.m_sample_visible}]")

        # ------------------------------------------------------------------
        def _distr(self):
            return mi.MicrofacetDistribution(mi.MicrofacetType.Beckmann, self.m_alpha,
                                             self.m_sample_visible)

        def _index(self, si, active):
            n = self.m_eta.eval(si, active)
            # Mitsuba's polarized Fresnel uses |k| (it conjugates n + ik into n - ik)
            k = dr.abs(self.m_k.eval(si, active))
            return n, k

        def _shadowing(self, distr, wi, wo, h):
            if self.m_shadowing == "smith":
                return distr.G(wi, wo, h)
            if self.m_shadowing == "vgroove":
                return po.vgroove_g(wi, wo, h)
            # "none": G = 1, but still only facets seen from the front by both directions
            return dr.select((dr.dot(wi, h) > 0) & (dr.dot(wo, h) > 0), 1.0, 0.0)

        def _one_minus_rho(self, cos_theta):
            return self.m_dhr.one_minus_rho(cos_theta, self.m_u_slope)

        def _diffuse_factor(self, ctx, si, wo):
            """(1/pi)(1 - rho(theta_in)) [paper, Eq. 17] or its reciprocal form; no M00, no cos."""
            # rho > 1 is possible without shadowing (Priest-Germer); 1 - rho is clipped at 0
            if self.m_diffuse == "paper":
                wo_hat_z = wo.z if ctx.mode == mi.TransportMode.Radiance else si.wi.z
                return dr.maximum(self._one_minus_rho(wo_hat_z), 0.0) * dr.inv_pi
            one_minus_i = dr.maximum(self._one_minus_rho(si.wi.z), 0.0)
            one_minus_o = dr.maximum(self._one_minus_rho(wo.z), 0.0)
            return one_minus_i * one_minus_o * dr.inv_pi / self.m_one_minus_avg

        def _p_spec(self, ctx, si):
            """Probability of sampling the specular lobe (a Python constant or a Float)."""
            spec_on = ctx.is_enabled(mi.BSDFFlags.GlossyReflection, 0)
            diff_on = self.m_diffuse != "none" and ctx.is_enabled(mi.BSDFFlags.DiffuseReflection, 1)
            if spec_on and not diff_on:
                return 1.0
            if diff_on and not spec_on:
                return 0.0
            if not (spec_on or diff_on):
                return None
            # ratio of the lobe albedos rho F : (1 - rho) F (F common to both)
            return dr.clip(1.0 - self._one_minus_rho(si.wi.z), 0.05, 0.95)

        def _mueller(self, ctx, si, wo, h, n, k, spec, diff):
            """Fresnel(h) * spec + M00(h) * diff as a Spectrum (Mueller matrix if polarized).

            ``spec`` multiplies the facet Fresnel Mueller matrix (paper Eq. 11) rotated
            into Mitsuba's Stokes bases; ``diff`` multiplies only its unpolarized
            M00 and goes into the [0, 0] element (the diffuse term of Eq. 17).
            """
            cos_beta = mi.UnpolarizedSpectrum(dr.dot(si.wi, h))
            if not self.m_polarized:
                return po.fresnel_average(cos_beta, n, k) * (spec + diff)
            rs_re, rs_im, rp_re, rp_im = po.facet_fresnel(cos_beta, n, k)
            a, b, c, s = po.fresnel_mueller_entries(rs_re, rs_im, rp_re, rp_im)
            F = dr.zeros(mi.Spectrum)
            F[0, 0] = a * spec
            F[0, 1] = b * spec
            F[1, 0] = b * spec
            F[1, 1] = a * spec
            F[2, 2] = c * spec
            F[2, 3] = -s * spec
            F[3, 2] = s * spec
            F[3, 3] = c * spec
            # Light arrives along -wo_hat and leaves along +wi_hat (roughconductor's frames)
            if ctx.mode == mi.TransportMode.Radiance:
                wo_hat, wi_hat = wo, si.wi
            else:
                wo_hat, wi_hat = si.wi, wo
            # The facet's s axis is perpendicular to its plane of incidence: roughconductor
            # uses h x (-wo_hat) = h x wi_hat, both parallel to wo_hat x wi_hat, which is
            # computed here with a compensated cross product (accurate near backscatter).
            s_axis = po.accurate_cross(wo_hat, wi_hat)
            # singular when both directions are collinear with the facet normal: any s axis will do
            collinear = dr.all(s_axis == mi.Vector3f(0))
            s_axis = dr.select(collinear, mi.Vector3f(1, 0, 0), dr.normalize(s_axis))
            s_in = s_out = s_axis
            F = mi.mueller.rotate_mueller_basis(F, -wo_hat, s_in, mi.mueller.stokes_basis(-wo_hat),
                                                wi_hat, s_out, mi.mueller.stokes_basis(wi_hat))
            if not (isinstance(diff, float) and diff == 0.0):
                # unpolarized diffuse term: only the [0, 0] element (Eq. 17)
                F[0, 0] = F[0, 0] + a * diff
            return F

        def _value(self, ctx, si, wo, active):
            """f cos(theta_o) as a Spectrum (Mueller matrix in polarized variants)."""
            spec_on = ctx.is_enabled(mi.BSDFFlags.GlossyReflection, 0)
            diff_on = self.m_diffuse != "none" and ctx.is_enabled(mi.BSDFFlags.DiffuseReflection, 1)
            if not (spec_on or diff_on):
                return dr.zeros(mi.Spectrum)
            cos_i = mi.Frame3f.cos_theta(si.wi)
            cos_o = mi.Frame3f.cos_theta(wo)
            active = active & (cos_i > 0) & (cos_o > 0)
            h = dr.normalize(wo + si.wi)
            n, k = self._index(si, active)
            spec = 0.0
            if spec_on:
                distr = self._distr()
                # D G / (4 cos_i) = (Eq. 13 without M) * cos_o
                spec = distr.eval(h) * self._shadowing(distr, si.wi, wo, h) / (4.0 * cos_i)
            diff = self._diffuse_factor(ctx, si, wo) * cos_o if diff_on else 0.0
            return dr.select(active, self._mueller(ctx, si, wo, h, n, k, spec, diff), 0.0)

        def _pdf(self, ctx, si, wo, active):
            p_spec = self._p_spec(ctx, si)
            if p_spec is None:
                return mi.Float(0.0)
            cos_i = mi.Frame3f.cos_theta(si.wi)
            cos_o = mi.Frame3f.cos_theta(wo)
            h = dr.normalize(wo + si.wi)
            active = active & (cos_i > 0) & (cos_o > 0)
            pdf_spec = 0.0
            if not (isinstance(p_spec, float) and p_spec == 0.0):
                spec_ok = active & (dr.dot(si.wi, h) > 0) & (dr.dot(wo, h) > 0)
                distr = self._distr()
                if self.m_sample_visible:
                    pdf_spec = distr.eval(h) * distr.smith_g1(si.wi, h) / (4.0 * cos_i)
                else:
                    pdf_spec = distr.pdf(si.wi, h) / (4.0 * dr.dot(wo, h))
                pdf_spec = dr.select(spec_ok, pdf_spec, 0.0)
            if isinstance(p_spec, float) and p_spec == 1.0:
                return dr.select(active, pdf_spec, 0.0)
            pdf_diff = mi.warp.square_to_cosine_hemisphere_pdf(wo)
            return dr.select(active, p_spec * pdf_spec + (1.0 - p_spec) * pdf_diff, 0.0)

        # ------------------------------------------------------------------
        def eval(self, ctx, si, wo, active=True):
            return self._value(ctx, si, wo, active)

        def pdf(self, ctx, si, wo, active=True):
            return self._pdf(ctx, si, wo, active)

        def eval_pdf(self, ctx, si, wo, active=True):
            return self._value(ctx, si, wo, active), self._pdf(ctx, si, wo, active)

        def sample(self, ctx, si, sample1, sample2, active=True):
            bs = dr.zeros(mi.BSDFSample3f)
            cos_i = mi.Frame3f.cos_theta(si.wi)
            active = active & (cos_i > 0)
            p_spec = self._p_spec(ctx, si)
            if p_spec is None:
                return bs, dr.zeros(mi.Spectrum)
            distr = self._distr()

            if isinstance(p_spec, float) and p_spec == 1.0:
                # specular lobe only: exactly roughconductor's sampling routine
                m, pdf = distr.sample(si.wi, sample2)
                bs.wo = mi.reflect(si.wi, m)
                bs.eta = 1.0
                bs.sampled_component = mi.UInt32(0)
                bs.sampled_type = mi.UInt32(+mi.BSDFFlags.GlossyReflection)
                active = active & (pdf != 0) & (mi.Frame3f.cos_theta(bs.wo) > 0)
                bs.pdf = pdf / (4.0 * dr.dot(bs.wo, m))
                # weight = f cos_o / pdf, written with the sampled m like roughconductor
                if self.m_shadowing == "smith" and self.m_sample_visible:
                    g_ratio = distr.smith_g1(bs.wo, m)
                elif self.m_sample_visible:
                    g_ratio = self._shadowing(distr, si.wi, bs.wo, m) / distr.smith_g1(si.wi, m)
                else:
                    g_ratio = (self._shadowing(distr, si.wi, bs.wo, m) * dr.dot(si.wi, m)
                               / (cos_i * mi.Frame3f.cos_theta(m)))
                n, k = self._index(si, active)
                weight = self._mueller(ctx, si, bs.wo, m, n, k, g_ratio, 0.0)
                bs.pdf = dr.select(active, bs.pdf, 0.0)
                return bs, dr.select(active, weight, 0.0)

            # mixture of the specular (glossy) and diffuse lobes
            choose_spec = sample1 < p_spec
            m, pdf_m = distr.sample(si.wi, sample2)
            # a back-facing normal (possible without visible-normal sampling) is a failed sample
            # (sample1 >= p_spec), not ~choose_spec: in scalar variants choose_spec is a Python bool
            active = active & ((sample1 >= p_spec) | ((pdf_m != 0) & (dr.dot(si.wi, m) > 0)))
            wo_spec = mi.reflect(si.wi, m)
            wo_diff = mi.warp.square_to_cosine_hemisphere(sample2)
            bs.wo = dr.select(choose_spec, wo_spec, wo_diff)
            bs.eta = 1.0
            bs.sampled_component = dr.select(choose_spec, mi.UInt32(0), mi.UInt32(1))
            bs.sampled_type = dr.select(choose_spec, mi.UInt32(+mi.BSDFFlags.GlossyReflection),
                                        mi.UInt32(+mi.BSDFFlags.DiffuseReflection))
            active = active & (mi.Frame3f.cos_theta(bs.wo) > 0)
            value, bs.pdf = self.eval_pdf(ctx, si, bs.wo, active)
            ok = active & (bs.pdf > 0)
            bs.pdf = dr.select(ok, bs.pdf, 0.0)
            weight = value / dr.select(ok, bs.pdf, 1.0)
            return bs, dr.select(ok, weight, 0.0)

    HydeBSDF.__name__ = "HydeBSDF"
    return HydeBSDF


_CLASSES: dict = {}


def plugin_class():
    """The HydeBSDF class for the current Mitsuba variant (built once per variant)."""
    variant = mi.variant()
    if variant is None:
        raise RuntimeError("hyde: call mi.set_variant(...) before using the hyde plugin")
    if variant not in _CLASSES:
        _CLASSES[variant] = _make_class()
    return _CLASSES[variant]


def register(variant: str | None = None) -> None:
    """Register the ``hyde`` BSDF with Mitsuba for ``variant`` (default: the current one).

    Registration is per variant: call it after ``mi.set_variant`` (or pass the
    variant; the current variant is then restored).  Calling it again is harmless.
    """
    current = mi.variant()
    if variant is None:
        if current is None:
            raise RuntimeError("hyde: no Mitsuba variant is set; call mi.set_variant(...) "
                               "(or hyde_bsdf.mitsuba.variants.set_variant) before register()")
        variant = current
    if variant != current:
        mi.set_variant(variant)
    try:
        cls = plugin_class()
        mi.register_bsdf("hyde", lambda props: cls(props))
    finally:
        if current is not None and variant != current:
            mi.set_variant(current)
