"""hyde-bsdf: the polarimetric BRDF of Hyde, Schmidt and Havrilla (Opt. Express 17(24), 2009).

Public entry points
-------------------
``pbrdf``              NumPy evaluator of the full 4x4 Mueller pBRDF (paper Eqs. 6-17).
``dhr_specular_pec``   directional-hemispherical reflectance of the specular lobe (Eqs. 14-16).
``rms_slope_from``     the paper's roughness sqrt(2)*sigma_h/ell from (sigma_h, ell).
``register``           register the ``hyde`` BSDF with Mitsuba (every usable variant).

Subpackages (the dependency direction is model -> mitsuba / mom / fit -> render -> report):

``hyde_bsdf.model``    the NumPy model, one module per paper equation group, and the DHR table
``hyde_bsdf.mitsuba``  the Mitsuba plugin ``hyde`` (an independent derivation of the model)
``hyde_bsdf.mom``      the method-of-moments reference and the 1-D model (``mom.scatter``)
``hyde_bsdf.fit``      fitting Mueller measurements (``fit.fit_mueller``)
``hyde_bsdf.render``   polarized rendering, Stokes I/O, demo, inverse rendering (``render.render_stokes``)
``hyde_bsdf.report``   the validation report

Importing this package does not import Mitsuba; ``register`` does.  The subpackages are
imported on first attribute access (``hyde_bsdf.mom.scatter`` works after ``import hyde_bsdf``).
Conventions (angles, Stokes bases, sign of the index) are in README.md, section
"Conventions", and in the docstring of :mod:`hyde_bsdf.model.evaluator`.
"""
from __future__ import annotations

from hyde_bsdf.model.roughness import alpha_from_rms_slope, rms_slope_from, rms_slope_from_alpha
from hyde_bsdf.model.dhr import dhr_specular_pec
from hyde_bsdf.model.evaluator import pbrdf

__all__ = [
    "pbrdf",
    "dhr_specular_pec",
    "rms_slope_from",
    "alpha_from_rms_slope",
    "rms_slope_from_alpha",
    "register",
]
__version__ = "0.1.0"


_SUBPACKAGES = ("model", "mitsuba", "mom", "fit", "render", "report")


def __getattr__(name):
    if name in _SUBPACKAGES:
        import importlib

        return importlib.import_module(f"hyde_bsdf.{name}")
    raise AttributeError(f"module 'hyde_bsdf' has no attribute {name!r}")


def register(variant: str | None = None) -> list:
    """Register the ``hyde`` BSDF plugin with Mitsuba; returns the variants registered.

    With no argument: in every variant usable on this machine (so any later
    ``mi.set_variant`` finds it; ``cuda_*`` only with a GPU); with a name: in that one.
    Idempotent.  See :mod:`hyde_bsdf.mitsuba.plugin` for the parameter table.
    """
    from hyde_bsdf.mitsuba.plugin import register as _register

    return _register(variant)
