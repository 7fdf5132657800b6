"""The exact mappings between this package's conventions and SCATMECH's and Mitsuba's.

Stated once here and in ``docs/conventions.md`` (``tests/test_conventions.py`` checks them against
the evaluator):

SCATMECH (NIST, ``Facet_BRDF_Model``; its Mueller matrix equals :func:`hyde_bsdf.pbrdf`'s to
1.6e-13 under these three maps, and nothing else changes):

* angles: phi_hyde = pi + phi_SCATMECH (SCATMECH puts the specular direction at phi = 0, the paper
  at phi = pi); theta_i, theta_r are the same polar angles;
* Stokes S3: the opposite sign, F_SCATMECH = Q F_hyde Q with Q = diag(1, 1, 1, -1) (the rows and
  columns of S3 flip; M_33 and the other elements stay);
* roughness: SCATMECH's Gaussian facet slope parameter = sqrt(2) x rms_slope (= Beckmann alpha).
* the index: n + ik in both (the paper's eta = n - jk is the same two numbers).

Mitsuba (the plugin ``hyde``, roughconductor):

* roughness: alpha = sqrt(2) x rms_slope (:func:`hyde_bsdf.model.parameters.alpha_from_rms_slope`);
* index: ``eta``, ``k`` are n, k (n + ik), the same numbers;
* Stokes bases: Mitsuba's ``stokes_basis(-wo_hat)`` in, ``stokes_basis(wi_hat)`` out, rotated into
  the paper's s/p bases by :mod:`hyde_bsdf.validation._frames`; the S3 sign is the paper's (no flip).
"""
from __future__ import annotations

import math

import numpy as np

from hyde_bsdf.model.parameters import SQRT2

__all__ = ["Q", "phi_from_scatmech", "phi_to_scatmech", "mueller_to_scatmech", "mueller_from_scatmech",
           "scatmech_slope", "rms_slope_from_scatmech"]

#: the S3 flip between the package's and SCATMECH's Stokes vectors
Q = np.diag([1.0, 1.0, 1.0, -1.0])


def phi_from_scatmech(phi_scatmech):
    """phi_hyde = pi + phi_SCATMECH (radians; the specular plane is phi_hyde = pi, phi_SCATMECH = 0)."""
    return math.pi + np.asarray(phi_scatmech, float)


def phi_to_scatmech(phi_hyde):
    """phi_SCATMECH = phi_hyde - pi (radians)."""
    return np.asarray(phi_hyde, float) - math.pi


def mueller_to_scatmech(F):
    """SCATMECH's Mueller matrix of the package's ``F`` (shape (..., 4, 4)): Q F Q, the S3 sign flipped."""
    return Q @ np.asarray(F, float) @ Q


def mueller_from_scatmech(F):
    """The package's Mueller matrix from SCATMECH's (the map is its own inverse)."""
    return mueller_to_scatmech(F)


def scatmech_slope(rms_slope):
    """SCATMECH's facet slope parameter = sqrt(2) x the paper's rms_slope (= Beckmann alpha)."""
    return SQRT2 * rms_slope


def rms_slope_from_scatmech(slope):
    """The paper's rms_slope from SCATMECH's slope parameter (slope / sqrt(2))."""
    return slope / SQRT2
