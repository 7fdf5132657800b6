"""Fitting the model to Mueller-matrix measurements, and measured pBRDF tables.

``mueller_fit`` (:func:`fit_mueller`, standard errors and ill-posedness checks); ``pbsdf_samples``
(a Mitsuba ``measured_polarized`` table in the paper's angles and bases: :func:`pbsdf_samples` --
frames, masking, subsampling), ``pbsdf_fit`` (:func:`fit_pbsdf`, n and k per band and rms_slope)
and ``pbsdf_export`` (:func:`export_pbsdf`, the model as such a table for the C++ renderer).
The files themselves (the measurement CSV, the ``.pbsdf`` format) are read and written by
:mod:`hyde_bsdf.io`; the commands (``hyde-bsdf fit``, ``hyde-bsdf export``) and the plots are in
:mod:`hyde_bsdf.app`.  ``adequacy``: the verdict every fit carries (does the model describe the
data, and what its standard errors mean); ``model_selection`` (:func:`select_model`,
:func:`select_model_pbsdf`): every shadowing x diffuse model, the smallest adequate one chosen
(``--model auto``).
"""
from hyde_bsdf.fit.mueller_fit import *  # noqa: F401,F403
from hyde_bsdf.fit.mueller_fit import __all__ as _fit_all
from hyde_bsdf.fit.pbsdf_export import export_pbsdf
from hyde_bsdf.fit.pbsdf_fit import fit_pbsdf
from hyde_bsdf.fit.pbsdf_samples import pbsdf_samples
from hyde_bsdf.io.pbsdf_file import read_pbsdf
from hyde_bsdf.fit.model_selection import select_model, select_model_pbsdf

__all__ = list(_fit_all) + ["read_pbsdf", "pbsdf_samples", "fit_pbsdf", "export_pbsdf", "select_model",
                            "select_model_pbsdf"]
