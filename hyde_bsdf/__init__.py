"""hyde-bsdf: the polarimetric BRDF of Hyde, Schmidt and Havrilla (Opt. Express 17(24), 2009).

Public entry points
-------------------
``pbrdf``              NumPy evaluator of the full 4x4 Mueller pBRDF (paper Eqs. 6-17).
``dhr_specular_pec``   directional-hemispherical reflectance of the specular lobe (Eqs. 14-16).
``rms_slope_from``     the paper's roughness sqrt(2)*sigma_h/ell from (sigma_h, ell).
``register``           register the ``hyde`` BSDF with Mitsuba for the current variant.

Importing this package does not import Mitsuba; ``register`` does.
Conventions (angles, Stokes bases, sign of the index) are in README.md, section
"Conventions", and in the docstring of :mod:`hyde_bsdf.evaluator`.
"""
from __future__ import annotations

from .roughness import alpha_from_rms_slope, rms_slope_from, rms_slope_from_alpha
from .dhr import dhr_specular_pec
from .evaluator import pbrdf

__all__ = [
    "pbrdf",
    "dhr_specular_pec",
    "rms_slope_from",
    "alpha_from_rms_slope",
    "rms_slope_from_alpha",
    "register",
]
__version__ = "0.1.0"


def register(variant: str | None = None) -> None:
    """Register the ``hyde`` BSDF plugin for the current (or the given) Mitsuba variant.

    Idempotent; call it again after every ``mi.set_variant``.  See
    :mod:`hyde_bsdf.plugin` for the parameter table.
    """
    from .plugin import register as _register

    _register(variant)
