"""hyde-bsdf: the polarimetric BRDF of Hyde, Schmidt and Havrilla (Opt. Express 17(24), 2009).

Public entry points
-------------------
``pbrdf``              NumPy evaluator of the full 4x4 Mueller pBRDF (paper Eqs. 6-17).
``dhr_specular_pec``   directional-hemispherical reflectance of the specular lobe (Eqs. 14-16).
``rms_slope_from``     the paper's roughness sqrt(2)*sigma_h/ell from (sigma_h, ell).
``register``           register the ``hyde`` BSDF with Mitsuba (every usable variant).

Subpackages, in layers (a module imports only from layers to its left; ``errors`` and
``progress`` from anywhere): io -> model -> mitsuba / mom / fit -> render -> inverse -> app:

``hyde_bsdf.io``       files: atomic writes, Stokes EXR, ``.pbsdf`` tables, measurement CSVs
``hyde_bsdf.model``    the NumPy model, one module per paper equation group, and the DHR table
``hyde_bsdf.mitsuba``  the Mitsuba plugin ``hyde`` (an independent derivation of the model)
``hyde_bsdf.mom``      the method-of-moments reference and the 1-D model (``mom.scatter``)
``hyde_bsdf.fit``      fitting Mueller measurements (``fit.fit_mueller``)
``hyde_bsdf.render``   polarized rendering and polarization quantities (``render.render_stokes``)
``hyde_bsdf.inverse``  inverse rendering: global or per-texel roughness and index, uncertainty (``inverse.invert_maps``)
``hyde_bsdf.app``      the ``hyde-bsdf`` command line, plots, the demo and the validation report

Importing this package does not import Mitsuba; ``register`` does.  The subpackages are
imported on first attribute access (``hyde_bsdf.mom.scatter`` works after ``import hyde_bsdf``).
Conventions (angles, Stokes bases, sign of the index) are in README.md, section
"Conventions", and in the docstring of :mod:`hyde_bsdf.model.evaluator`.
"""
from __future__ import annotations

__all__ = [
    "pbrdf",
    "dhr_specular_pec",
    "rms_slope_from",
    "alpha_from_rms_slope",
    "rms_slope_from_alpha",
    "register",
]


def _version() -> str:
    """The installed distribution's version (pyproject.toml's, through the package metadata);
    a checkout that was never installed reads pyproject.toml itself."""
    from importlib import metadata

    try:
        return metadata.version("hyde-bsdf")
    except metadata.PackageNotFoundError:
        import re
        from pathlib import Path

        try:
            text = (Path(__file__).resolve().parent.parent / "pyproject.toml").read_text(encoding="utf-8")
        except OSError:
            return "unknown"
        found = re.search(r'^version\s*=\s*"([^"]+)"', text, re.M)
        return found.group(1) if found else "unknown"


#: the package's version (pyproject.toml's, from the package metadata): read on first use
__version__: str

_SUBPACKAGES = ("io", "model", "mitsuba", "mom", "fit", "render", "inverse", "app")
#: public functions, imported on first use: ``import hyde_bsdf`` (and so the command line's
#: start-up, before it can catch Ctrl-C) loads only the standard library
_FUNCTIONS = {"pbrdf": "hyde_bsdf.model.evaluator", "dhr_specular_pec": "hyde_bsdf.model.dhr",
              "rms_slope_from": "hyde_bsdf.model.roughness",
              "alpha_from_rms_slope": "hyde_bsdf.model.roughness",
              "rms_slope_from_alpha": "hyde_bsdf.model.roughness"}


def __getattr__(name):
    import importlib

    if name == "__version__":      # read on first use: the metadata lookup costs a plugin's cold load ~60 ms
        globals()[name] = _version()
        return globals()[name]
    if name in _SUBPACKAGES:
        return importlib.import_module(f"hyde_bsdf.{name}")
    if name in _FUNCTIONS:
        value = getattr(importlib.import_module(_FUNCTIONS[name]), name)
        globals()[name] = value
        return value
    raise AttributeError(f"module 'hyde_bsdf' has no attribute {name!r}")


def __dir__():
    return sorted(set(globals()) | set(_SUBPACKAGES) | set(_FUNCTIONS) | {"__version__"})


def register(variant: str | None = None) -> list:
    """Register the ``hyde`` BSDF plugin with Mitsuba; returns the variants registered.

    With no argument: in every variant usable on this machine (so any later
    ``mi.set_variant`` finds it; ``cuda_*`` only with a GPU); with a name: in that one.
    Idempotent.  See :mod:`hyde_bsdf.mitsuba.plugin` for the parameter table.
    """
    from hyde_bsdf.mitsuba.plugin import register as _register

    return _register(variant)
