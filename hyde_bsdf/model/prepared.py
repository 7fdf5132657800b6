"""The model at fixed geometries, split into the factors that each parameter moves (for fits).

A fit evaluates the model at the same measured geometries for hundreds of parameter values.
Of paper Eq. 17 (with Eq. 6 and the diffuse terms),

    F    = lobe(rms_slope) * U(n, k)                      the specular term, Eqs. 6-13
    F_00 += diffuse(rms_slope) * U_00(n, k)               Eq. 17 (or its reciprocal variant)
    F_00 += diffuse_reflectance / pi                      the free Lambertian term (or)

the angles (Eqs. 7, 10) depend on the geometry alone and are computed once here; the lobe
``P G / (4 cos ti cos tr cos alpha)`` (Eqs. 6, 8, 12) and the diffuse factor depend on the
roughness alone; the unit facet Mueller matrix ``U`` (Eqs. 9-11, with the rotations of Eq. 10)
depends on the index alone.  A change of n and k then costs one Fresnel evaluation, a change of
roughness one lobe, and the product is exact: :meth:`PreparedGeometry.mueller` equals
:func:`hyde_bsdf.pbrdf` to rounding (``tests/test_lab_fit.py`` checks it).  Every factor is the
evaluator's own function; nothing is derived twice.
"""
from __future__ import annotations

import numpy as np

from hyde_bsdf.model.evaluator import diffuse_pbrdf
from hyde_bsdf.model.facet_geometry import HORIZON_COS, angle_trig, cos_alpha_beta, rotation_terms
from hyde_bsdf.model.fresnel import fresnel_mueller_terms
from hyde_bsdf.model.index import Index
from hyde_bsdf.model.jones_mueller import rotated_fresnel_mueller
from hyde_bsdf.model.slope_distribution import beckmann_P
from hyde_bsdf.model.terms import diffuse_term, shadowing_term

__all__ = ["PreparedGeometry"]


class PreparedGeometry:
    """Geometries (radians, 1-D arrays of one length, above the horizon) prepared once.

    ``lobe``, ``diffuse`` and ``unit_mueller`` are the factors above; :meth:`mueller` assembles F.
    """

    def __init__(self, theta_i, theta_r, phi):
        ti, tr, ph = (np.asarray(a, float).ravel() for a in np.broadcast_arrays(theta_i, theta_r, phi))
        self.theta_i, self.theta_r = ti, tr
        with np.errstate(divide="ignore", invalid="ignore"):
            trig = angle_trig(ti, tr, ph)
            self.cos_i, self.cos_r = trig[1], trig[3]
            self.above = (self.cos_i > HORIZON_COS) & (self.cos_r > HORIZON_COS)
            self.cos_a, cos_b, self.tan2_a = cos_alpha_beta(*trig)
            self.cos_b = np.where(self.above, cos_b, 1.0)
            self.rotation = rotation_terms(*trig)

    def __len__(self) -> int:
        return self.theta_i.size

    def lobe(self, rms_slope: float, shadowing: str) -> np.ndarray:
        """P G / (4 cos ti cos tr cos alpha): Eq. 6 without the Mueller matrix (1/sr); 0 below the horizon."""
        with np.errstate(divide="ignore", invalid="ignore", over="ignore", under="ignore"):
            G = shadowing_term(shadowing).g(self.cos_a, self.cos_b, self.cos_i, self.cos_r, rms_slope)
            scale = beckmann_P(self.cos_a, self.tan2_a, rms_slope) * G / (4.0 * self.cos_i * self.cos_r * self.cos_a)
        return np.where(self.above, scale, 0.0)

    def diffuse(self, rms_slope: float, mode: str, shadowing: str) -> np.ndarray:
        """A diffuse term that scales with the facet M_00 (the paper's Eqs. 16-17, its reciprocal
        variant), per unit M_00; zeros for "none" and for a term with parameters of its own (the
        Lambertian: :meth:`per_albedo`)."""
        term = diffuse_term(mode)
        if not term.present or term.parameters:
            return np.zeros(len(self))
        return np.where(self.above, diffuse_pbrdf(self.theta_i, self.theta_r, 1.0, rms_slope, term, shadowing), 0.0)

    def per_albedo(self, mode: str) -> np.ndarray:
        """The Lambertian term per unit albedo (1/pi above the horizon): it is linear in its albedo."""
        term = diffuse_term(mode)
        if "diffuse_reflectance" not in term.parameters:
            return np.zeros(len(self))
        return np.where(self.above, diffuse_pbrdf(self.theta_i, self.theta_r, 1.0, 1.0, term,
                                                  diffuse_reflectance=1.0), 0.0)

    def unit_mueller(self, n: float, k: float) -> np.ndarray:
        """The facet's Fresnel Mueller matrix rotated into the paper's bases (Eqs. 9-11), shape (4, 4, N)."""
        out = np.empty((4, 4, len(self)))
        with np.errstate(divide="ignore", invalid="ignore", over="ignore", under="ignore"):
            A, B, C, S = fresnel_mueller_terms(self.cos_b, Index(n, k))
        return rotated_fresnel_mueller(A, B, C, S, *self.rotation, 1.0, out)

    def mueller(self, rms_slope, n, k, shadowing="vgroove", diffuse="paper", diffuse_reflectance=None):
        """F (4, 4, N) in 1/sr: the factors assembled (module docstring)."""
        U = self.unit_mueller(n, k)
        F = self.lobe(rms_slope, shadowing) * U
        F[0, 0] += self.diffuse(rms_slope, diffuse, shadowing) * U[0, 0]
        if diffuse_term(diffuse).parameters:
            F[0, 0] += self.per_albedo(diffuse) * (0.5 if diffuse_reflectance is None else diffuse_reflectance)
        return F
