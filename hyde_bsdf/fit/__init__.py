"""Fitting the model to Mueller-matrix measurements.

``mueller_fit`` (:func:`fit_mueller`, standard errors and ill-posedness checks, the
``hyde-bsdf fit`` command) and ``measurements`` (the CSV format, its reader and writer).

May import: ``hyde_bsdf.model``.  Independent of Mitsuba.
"""
from hyde_bsdf.fit.mueller_fit import *  # noqa: F401,F403
from hyde_bsdf.fit.mueller_fit import __all__ as _fit_all

__all__ = list(_fit_all)
