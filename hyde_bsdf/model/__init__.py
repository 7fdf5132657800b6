"""The paper's model in NumPy: one module per equation group, float64, no Mitsuba.

``facet_geometry`` (Eqs. 7, 10), ``slope_distribution`` (Eq. 8), ``fresnel`` and
``jones_mueller`` (Eqs. 9, 11), ``shadowing`` (Eq. 12, Smith, none), ``diffuse`` (Eqs. 16-17
and a reciprocal variant), ``terms`` (one record per shadowing and diffuse term, with its
rules), ``index`` (the index value type n + ik), ``parameters`` (the registry of ranges),
``roughness`` (the roughness spellings), ``dhr`` (Eqs. 14-16 and the DHR table) and
``evaluator`` (Eqs. 6, 13, 16, 17: :func:`pbrdf`).
"""
from hyde_bsdf.model.dhr import dhr_specular_pec
from hyde_bsdf.model.evaluator import diffuse_pbrdf, pbrdf, specular_pbrdf
from hyde_bsdf.model.index import PEC, Index
from hyde_bsdf.model.roughness import alpha_from_rms_slope, rms_slope_from, rms_slope_from_alpha

__all__ = ["pbrdf", "specular_pbrdf", "diffuse_pbrdf", "dhr_specular_pec", "Index", "PEC", "rms_slope_from",
           "alpha_from_rms_slope", "rms_slope_from_alpha"]
