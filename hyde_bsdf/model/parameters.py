"""The parameter registry: the one definition of each model parameter's name, range, unit and
conversions, and the one spelling of the index and roughness per interface.

Every range the package checks or clamps a model parameter against is defined here, once;
``tests/test_parameters.py`` fails if a range literal for these parameters appears anywhere
else in ``hyde_bsdf/``.  A :class:`Range` unpacks and indexes as the pair ``(lo, hi)``, so
``lo, hi = RMS_SLOPE`` and ``RMS_SLOPE[1]`` work where a tuple did.

Ranges
------
* :data:`RMS_SLOPE` [1e-4, 50]: the accepted rms_slope -- evaluator, plugin, MoM model, both
  fits, the inverse's box;
* :data:`ALPHA`: the same range as Beckmann alpha (sqrt(2) x RMS_SLOPE);
* :data:`DHR_TABLE_RMS_SLOPE` [1e-4, 100]: the DHR table's grid, wider than the accepted range so
  that its top end, 50, is interior;
* :data:`N`, :data:`K` (:data:`ETA`, the plugin's name for n) [0, 1e6]: the accepted index parts
  (beyond ~1e9 the float32 Fresnel terms overflow); :data:`INDEX_MIN` 1e-6: the smallest |eta|
  (eta^2 underflows below it);
* :data:`NATURAL_INDEX` [0, 1e3]: the fits' search box for n and k and the MoM's accepted index
  (every natural material);
* :data:`INVERSE_ETA` [0.02, 50], :data:`INVERSE_K` [0, 50], :data:`INVERSE_SCALE` [1e-3, 1e3]:
  the inverse's optimisation boxes (log-space map updates floor k at :data:`INVERSE_K_LOG_FLOOR`);
* :data:`ALPHA_SAMPLE` [1e-4, 10]: the .pbsdf file's importance-sampling alpha;
* :data:`DIFFUSE_REFLECTANCE` [0, 1]: the Lambertian term's albedo (its hemispherical reflectance).

Conventions and spellings (one per interface, converted at the boundary)
------------------------------------------------------------------------
The index is one value, :class:`hyde_bsdf.model.index.Index` (n, k of n + ik, the PEC as
k -> infinity), whose docstring states the convention: the paper writes the same material as
eta = n - j kappa, Mitsuba and SCATMECH as n + i k, the same two numbers.  Roughness: rms_slope = sqrt(2) sigma_h / ell (the paper's), Beckmann
alpha = 2 sigma_h / ell = sqrt(2) rms_slope (Mitsuba's roughconductor).

* evaluator (:mod:`hyde_bsdf.model`): ``rms_slope``, ``n``, ``k``; the paper's eta = n - j k;
* plugin (:mod:`hyde_bsdf.mitsuba`): ``rms_slope`` or ``alpha``, ``eta``, ``k``; Mitsuba's
  eta + i k (the same numbers);
* fit: :data:`FIT_PARAMETERS` = (``n``, ``k``, ``rms_slope``), the evaluator's names;
* inverse: :data:`INVERSE_PARAMETERS` = (``rms_slope``, ``eta``, ``k``), the plugin's names;
* MoM solver: ``n``, ``k`` in (n=None: the PEC); inside, the complex :meth:`Index.paper_eta` = n - j k.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

from hyde_bsdf.model.checks import real_scalar

__all__ = ["Range", "RMS_SLOPE", "ALPHA", "DHR_TABLE_RMS_SLOPE", "N", "K", "ETA", "INDEX_MIN", "NATURAL_INDEX",
           "INVERSE_ETA", "INVERSE_K", "INVERSE_K_LOG_FLOOR", "INVERSE_SCALE", "ALPHA_SAMPLE", "FIT_PARAMETERS",
           "INVERSE_PARAMETERS", "DIFFUSE_REFLECTANCE", "SPELLINGS", "SQRT2", "alpha_from_rms_slope",
           "rms_slope_from_alpha"]

SQRT2 = math.sqrt(2.0)


@dataclass(frozen=True)
class Range:
    """A closed range [lo, hi] of one parameter, with its unit and what it is for.

    Iterates and indexes as the pair (lo, hi)."""
    name: str
    lo: float
    hi: float
    unit: str
    purpose: str

    def __iter__(self):
        return iter((self.lo, self.hi))

    def __getitem__(self, i):
        return (self.lo, self.hi)[i]

    def __len__(self):
        return 2

    @property
    def bounds(self) -> tuple:
        return (self.lo, self.hi)

    def text(self) -> str:
        """``[lo, hi]`` with 7 significant digits (a printed bound is itself accepted)."""
        return f"[{self.lo:.7g}, {self.hi:.7g}]"

    def contains(self, value) -> bool:
        """True for a finite real number inside the range (False for NaN, strings, ...)."""
        try:
            return self.lo <= float(value) <= self.hi
        except (TypeError, ValueError):
            return False

    def check(self, value, name: str | None = None) -> float:
        """``value`` as a float; TypeError for a non-real, ValueError naming it and the range otherwise."""
        return real_scalar(name or self.name, value, self.lo, self.hi)

    def scaled(self, factor: float, name: str, unit: str | None = None) -> "Range":
        """The same range in another unit (e.g. alpha = sqrt(2) rms_slope)."""
        return Range(name, factor * self.lo, factor * self.hi, unit or self.unit, self.purpose)


RMS_SLOPE = Range("rms_slope", 1e-4, 50.0, "dimensionless (slope)",
                  "accepted rms_slope = sqrt(2) sigma_h / ell: evaluator, plugin, MoM model, fits, inverse")
ALPHA = RMS_SLOPE.scaled(SQRT2, "alpha")
DHR_TABLE_RMS_SLOPE = Range("rms_slope", 1e-4, 100.0, "dimensionless (slope)",
                            "the DHR table's grid; wider than RMS_SLOPE so that its top end is interior")
N = Range("n", 0.0, 1e6, "dimensionless", "real part of the index (paper n, Mitsuba eta)")
K = Range("k", 0.0, 1e6, "dimensionless", "extinction coefficient (paper kappa, Mitsuba k)")
ETA = Range("eta", N.lo, N.hi, N.unit, "the plugin's spelling of n (Mitsuba's n + ik)")
INDEX_MIN = 1e-6
NATURAL_INDEX = Range("n, k", 0.0, 1e3, "dimensionless",
                      "the fits' search box and the MoM's accepted index: every natural material")
INVERSE_ETA = Range("eta", 0.02, 50.0, "dimensionless", "the inverse's optimisation box for eta")
INVERSE_K = Range("k", 0.0, 50.0, "dimensionless", "the inverse's optimisation box for k")
#: log-space updates (texture maps) need k > 0: their box for k starts here
INVERSE_K_LOG_FLOOR = 1e-4
INVERSE_SCALE = Range("specular_reflectance", 1e-3, 1e3, "dimensionless",
                      "the inverse's box for a per-texel multiplier (an unknown albedo or light)")
ALPHA_SAMPLE = Range("alpha_sample", 1e-4, 10.0, "dimensionless (Beckmann alpha)",
                     "the .pbsdf file's importance-sampling alpha")
DIFFUSE_REFLECTANCE = Range("diffuse_reflectance", 0.0, 1.0, "dimensionless (albedo)",
                            "the Lambertian term's albedo (F_00 += diffuse_reflectance / pi): evaluator, plugin, "
                            "fits, export")

#: the fit's parameters (evaluator names, paper index n - jk), in this order everywhere
FIT_PARAMETERS = ("n", "k", "rms_slope")
#: the inverse's parameters (plugin names, Mitsuba index eta + ik), in this order everywhere
INVERSE_PARAMETERS = ("rms_slope", "eta", "k")
#: interface -> its parameter names (module docstring, "Conventions and spellings")
SPELLINGS = {"evaluator": ("rms_slope", "n", "k"), "plugin": ("rms_slope", "alpha", "eta", "k"),
             "fit": FIT_PARAMETERS, "inverse": INVERSE_PARAMETERS, "mom": ("n", "k")}


def alpha_from_rms_slope(rms_slope):
    """Beckmann alpha (Mitsuba's ``alpha``) = sqrt(2) * rms_slope."""
    return SQRT2 * rms_slope


def rms_slope_from_alpha(alpha):
    """The paper's rms slope = Beckmann alpha / sqrt(2)."""
    return alpha / SQRT2

