"""The paper's model in NumPy: one module per equation group, float64, no Mitsuba.

``facet_geometry`` (Eqs. 7, 10), ``slope_distribution`` (Eq. 8), ``fresnel`` and
``jones_mueller`` (Eqs. 9, 11), ``shadowing`` (Eq. 12, Smith, none), ``diffuse`` (Eqs. 16-17
and a reciprocal variant), ``terms`` (one record per shadowing and diffuse term, with its
rules), ``index`` (the index value type n + ik), ``parameters`` (the registry of ranges),
``roughness`` (the roughness spellings), ``dhr`` (Eqs. 14-16 and the DHR table) and
``evaluator`` (Eqs. 6, 13, 16, 17: :func:`pbrdf`).
"""
__all__ = ["pbrdf", "specular_pbrdf", "diffuse_pbrdf", "dhr_specular_pec", "Index", "PEC", "rms_slope_from",
           "alpha_from_rms_slope", "rms_slope_from_alpha"]

#: the public names, imported on first use: a module of this package that needs only the registry
#: or the term records (the Mitsuba plugin) does not import the evaluator
_HOMES = {"pbrdf": "evaluator", "specular_pbrdf": "evaluator", "diffuse_pbrdf": "evaluator",
          "dhr_specular_pec": "dhr", "Index": "index", "PEC": "index", "rms_slope_from": "roughness",
          "alpha_from_rms_slope": "roughness", "rms_slope_from_alpha": "roughness"}


def __getattr__(name):
    import importlib

    if name in _HOMES:
        value = getattr(importlib.import_module(f"hyde_bsdf.model.{_HOMES[name]}"), name)
        globals()[name] = value
        return value
    raise AttributeError(f"module 'hyde_bsdf.model' has no attribute {name!r}")


def __dir__():
    return sorted(set(globals()) | set(_HOMES))
