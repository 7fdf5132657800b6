"""Diffuse terms F^d_00 (paper Eqs. 16-17, a reciprocal variant, a free Lambertian term), one function each.

Each function returns the unpolarized diffuse element F^d_00 (it adds to M_00 only) from a
*hemisphere* ``h`` that describes the specular lobe's directional-hemispherical reflectance rho:

* ``h.one_minus(theta)``: 1 - rho(theta) (rho of a PEC, Eqs. 14-16; not clipped);
* ``h.measure``: the cosine-weighted measure of the hemisphere, int cos dw: pi on a 2-D surface
  (3-D scattering), 2 in the plane of incidence of a 1-D surface (``mom/model1d.py``);
* ``h.one_minus_avg``: 1 - rho_avg, rho_avg = (1 / measure) int rho cos dw (the albedo average).

The same function is then the term on the 2-D surface (the evaluator:
:class:`hyde_bsdf.model.dhr.DHRHemisphere`) and its reduction to the plane of a 1-D surface
(``mom/model1d.py``'s hemisphere), so the two cannot drift apart.  Each term's hemispherical
integral int F^d_00 cos(theta_r) dw_r for a PEC (M_00 = 1) is 1 - rho(theta_i): the energy balance
of Eq. 15.  Where rho > 1 (no shadowing, Priest-Germer, at grazing angles) 1 - rho is clipped at 0,
which keeps F^d >= 0.  The terms are registered, with their rules, in :mod:`hyde_bsdf.model.terms`.
"""
from __future__ import annotations

import numpy as np

__all__ = ["f00_paper", "f00_reciprocal", "f00_lambertian"]


def _one_minus(h, theta):
    """1 - rho(theta), clipped at 0 (rho > 1 only without shadowing)."""
    return np.maximum(h.one_minus(theta), 0.0)


def f00_paper(h, theta_i, theta_r, M00):
    """Paper Eqs. 16-17: F^d_00 = (1 - rho(theta_i)) M_00(beta) / pi (on the 2-D surface).

    Depends on the direction towards the source alone: not reciprocal."""
    return _one_minus(h, theta_i) * M00 / h.measure


def f00_reciprocal(h, theta_i, theta_r, M00):
    """The reciprocal variant: F^d_00 = (1 - rho(theta_i)) (1 - rho(theta_r)) M_00(beta) / (pi (1 - rho_avg)).

    Symmetric in the two directions, with the same hemispherical integral 1 - rho(theta_i) as
    Eq. 17.  A surface with rho = 1 everywhere (a mirror) has no diffuse part."""
    avg = h.one_minus_avg
    if avg <= 0.0:    # rho = 1 everywhere (a mirror-smooth surface): no multiple scattering
        return np.zeros(np.broadcast(theta_i, theta_r, M00).shape)
    return _one_minus(h, theta_i) * _one_minus(h, theta_r) * M00 / (h.measure * avg)


def f00_lambertian(h, theta_i, theta_r, M00, diffuse_reflectance):
    """A Lambertian term with its own albedo: F^d_00 = diffuse_reflectance / pi (on the 2-D surface).

    Not the paper's: its size is free (the albedo ``diffuse_reflectance``, its hemispherical
    integral), not tied to the roughness through the DHR, and it does not depend on the facet
    Fresnel average ``M00`` -- a subsurface or coating part, as in Mitsuba's plastic-like BSDFs.
    Unpolarized, reciprocal, linear in its albedo."""
    return np.full(np.broadcast(theta_i, theta_r, M00).shape, diffuse_reflectance / h.measure)
