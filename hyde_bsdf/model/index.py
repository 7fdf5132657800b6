"""The complex refractive index as one value: :class:`Index`, the pair (n, k) of n + ik.

Convention (stated here once)
-----------------------------
An :class:`Index` holds two real numbers, ``n`` >= 0 and ``k`` >= 0, of the index n + ik in the
e^{-iwt} convention of Mitsuba and SCATMECH.  The paper writes the same material as
eta = n - j kappa (time factor e^{+jwt}): the same two numbers, kappa = k, and the same Mueller
matrix.  A perfect electric conductor (PEC) is the limit k -> infinity (|r_s| = |r_p| = 1 for
every n): :data:`PEC` = ``Index(0.0, inf)``, and :attr:`Index.is_pec` says so.

One value inside, one spelling per boundary (converted only there)
-------------------------------------------------------------------
* the evaluator's, the fits' and the export's keywords ``n``, ``k``, ``pec``:
  :meth:`Index.from_keywords` (``pec=True`` and, where an interface defaults to the PEC,
  ``n=None`` are the PEC);
* the paper's complex eta = n - jk (the MoM's solver, ``mom/``): :meth:`Index.paper_eta`;
* Mitsuba's ``eta`` + i ``k`` (the plugin's parameters, the inverse, a fit's plugin
  dictionary): :meth:`Index.mitsuba` and :meth:`Index.from_mitsuba`.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

from hyde_bsdf.errors import UsageError, UsageTypeError, shorten
from hyde_bsdf.model.checks import check_bool
from hyde_bsdf.model.parameters import INDEX_MIN, K, N

__all__ = ["Index", "PEC", "admissible"]


@dataclass(frozen=True)
class Index:
    """The index n + ik (k >= 0: an absorbing or lossless material); ``k = inf`` is the PEC.

    Construct it from numbers (``Index(0.2, 3.4)``), from an interface's keywords
    (:meth:`from_keywords`), or from Mitsuba's spelling (:meth:`from_mitsuba`).
    """
    n: float
    k: float = 0.0

    def __post_init__(self):
        n, k = float(self.n), float(self.k)
        if not (math.isfinite(n) and n >= 0.0) or not (k >= 0.0):      # k >= 0 is False for NaN
            raise UsageError(f"an index n + ik needs a finite n >= 0 and k >= 0 (k = inf: the PEC), "
                             f"got n={self.n!r}, k={self.k!r}")
        object.__setattr__(self, "n", n)
        object.__setattr__(self, "k", k)

    @property
    def is_pec(self) -> bool:
        """True for the perfect conductor (k = inf)."""
        return math.isinf(self.k)

    @classmethod
    def from_keywords(cls, n=None, k=0.0, pec=False, index=None, *, pec_if_missing=False, n_range=N,
                      k_range=K) -> "Index":
        """The index of an interface's keywords, checked (each refusal names the keyword).

        ``index``: an :class:`Index` given as such (then n, k and pec must not be).  ``pec=True``
        is the PEC (then ``n`` must not be given); ``n=None`` is the PEC where the interface
        defaults to it (``pec_if_missing``: the MoM, the 1-D model) and an error elsewhere (the
        evaluator).  ``k=None`` is 0.  n and k must lie in ``n_range``/``k_range`` (the
        registry's :data:`~hyde_bsdf.model.parameters.N`, :data:`~hyde_bsdf.model.parameters.K`
        by default) and |n + ik| >= INDEX_MIN (eta^2 underflows below it).
        """
        if index is not None:
            if not isinstance(index, Index):
                raise UsageTypeError(f"index must be a hyde_bsdf.model.index.Index, got {shorten(index)}")
            if n is not None or pec is True or k not in (None, 0.0):
                raise UsageError("give either index or n/k/pec, not both")
            return index if index.is_pec else cls.from_keywords(index.n, index.k, n_range=n_range, k_range=k_range)
        if check_bool("pec", pec):
            if n is not None:
                raise UsageError("give either n (and k) or pec=True, not both")
            return PEC
        if n is None:
            if pec_if_missing:
                if k is not None and k != 0.0:
                    raise UsageError(f"k={k!r} needs n (the real part of the index n + ik); give n, "
                                     f"or neither for a PEC")
                return PEC
            raise UsageError("n is required (the index n + ik, the paper's eta = n - jk) unless pec=True")
        n = n_range.check(n, "n")
        k = 0.0 if k is None else k_range.check(k, "k")
        if math.hypot(n, k) < INDEX_MIN:       # eta^2 would underflow in the Fresnel terms
            raise UsageError(f"n and k: |eta| = sqrt(n^2 + k^2) must be >= {INDEX_MIN:g}, got n={n!r}, k={k!r}")
        return cls(n, k)

    @classmethod
    def from_mitsuba(cls, eta, k) -> "Index":
        """From Mitsuba's spelling eta + i k (the plugin's ``eta`` is n)."""
        return cls(eta, k)

    def mitsuba(self) -> dict:
        """Mitsuba's spelling, ``{"eta": n, "k": k}`` (a plugin dictionary's entries)."""
        if self.is_pec:
            raise UsageError("the plugin has no PEC: give a large k (e.g. k = 1e5) instead")
        return {"eta": self.n, "k": self.k}

    def paper_eta(self) -> complex | None:
        """The paper's complex eta = n - jk (e^{+jwt}); None for the PEC (the MoM's spelling)."""
        return None if self.is_pec else complex(self.n, -self.k)

    def text(self) -> str:
        """``"n = 0.2, k = 3.4"`` or ``"PEC"`` (for messages and reports)."""
        return "PEC" if self.is_pec else f"n = {self.n:.6g}, k = {self.k:.6g}"


#: the perfect electric conductor: the limit k -> infinity (r_s = -1, r_p = +1 at every angle)
PEC = Index(0.0, math.inf)


def admissible(n: float, k: float) -> tuple[float, float]:
    """(n, k), with n raised to INDEX_MIN where |n + ik| < INDEX_MIN: the nearest index the model accepts.
    For optimisers, whose search box (n, k >= 0) holds eta = 0 -- their step there is no user's mistake
    (was reported as one: "|eta| must be >= 1e-06, got n=3.8e-33")."""
    return (max(n, INDEX_MIN), k) if math.hypot(n, k) < INDEX_MIN else (n, k)
