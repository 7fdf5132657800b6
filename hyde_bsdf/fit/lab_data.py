"""Lab Mueller data as the joint fit sees it: one group of geometries per wavelength.

:func:`lab_data` turns :class:`~hyde_bsdf.io.measurements.Measurements` (a CSV with an optional
``M00`` column in 1/sr and an optional ``wavelength_nm`` column) into :class:`LabData`: per
wavelength the geometries (repeats merged, as :func:`hyde_bsdf.fit.merge_repeated_geometries`
does for one wavelength) and prepared once (:class:`hyde_bsdf.model.prepared.PreparedGeometry`),
and every measured value stacked into one vector ``y`` with its standard deviation ``w``, in the
order the residuals use: value column by value column (``M00`` first, then the elements), each
over the groups in wavelength order.  ``w`` is None when the file has no sigmas (the fit then
estimates them from its residuals: :meth:`LabData.with_noise`).

With M00 the elements are fitted as what the instrument measured, the absolute M_jk =
(M_jk/M00) M00 in 1/sr (``LabData.absolute``), each with its own noise: a ratio of two noisy
values is not Gaussian where M00 is small (its tail biased the albedo by 1.2 standard errors in
``hyde_bsdf/validation/fit_lab_data.py``), and the ratios of one row share M00's noise, which a fit of
ratios as independent values ignores (its errors came out 1.8x the Cramer-Rao bound of the
design).  The absolute sigma is the file's ratio sigma with the first-order propagation undone,
sigma_jk^2 = (M00 sigma_r)^2 - (r sigma_00)^2 -- exact for the usual propagation of independent
element noise -- floored at a tenth of M00 sigma_r where a file's sigmas were made otherwise.

Without M00 a row's normalized values are ratios over its M00, whose relative error the sigmas
imply: delta = sigma_jk / sqrt(1 + (M_jk/M00)^2) (the first-order propagation of one noise level;
the row's median over its elements).  Where M00 is not known to be above 0 within 3 standard
deviations (delta > :data:`RATIO_DELTA` = 1/3) the ratio is one of noises -- not Gaussian, centred
near 0: it looks depolarized, and with it the narrowest lobe plus any diffuse part "fits" better
than the truth (the roughness 8 standard errors off in ``hyde_bsdf/validation/fit_lab_data.py``) -- and the
row carries no usable information: it is left out, counted in ``Group.uninformative`` (the fit's
note says how many; measure M00 to use them).  The rows kept are fitted as what they are:

- the ratios of one row share M00's noise, so their covariance is not diagonal:
  C = diag(sigma_jk^2 - (delta r_jk)^2) + (delta r)(delta r)^T (the elements' own noise plus the
  shared part), and the residuals are whitened with it (:meth:`LabData.whiten`, Sherman-Morrison:
  one dot product per row), r the model's (a first fit's prediction, :meth:`LabData.with_shared`).  A diffuse part scales a row's ratios together, exactly as M00's
  noise does: fitted as independent values the albedo and the roughness it carries came out with
  errors 1.5x too small;
- a weighted fit of ratios whose weights come from the measured M00 shrinks them by
  1/(1 + delta^2) on average (a row whose M00 noise is up weighs more and has the smaller
  ratios: it looks depolarized); each row is scaled by (1 + delta^2), which undoes that to
  O(delta^4).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import numpy as np

from hyde_bsdf.errors import UsageError
from hyde_bsdf.fit.adequacy import neighbour_index
from hyde_bsdf.fit.mueller_fit import merge_repeated_geometries
from hyde_bsdf.io.measurements import M00, Measurements
from hyde_bsdf.model.prepared import PreparedGeometry

__all__ = ["Group", "LabData", "lab_data", "RATIO_DELTA"]

#: the relative error of M00 above which a row's normalized values (without M00) are left out:
#: M00 not above 0 within 3 standard deviations (module docstring)
RATIO_DELTA = 1.0 / 3.0


@dataclass
class Group:
    """The rows of one wavelength (``wavelength`` None: the file has no wavelength column)."""

    wavelength: float | None
    geometry: PreparedGeometry
    theta_i: np.ndarray
    theta_r: np.ndarray
    phi: np.ndarray
    rows_in: int
    repeats: dict | None
    #: rows left out: normalized values over an M00 not known to be above 0 (module docstring)
    uninformative: int = 0

    def __len__(self) -> int:
        return self.theta_i.size

    @property
    def label(self) -> str:
        return "(no wavelength)" if self.wavelength is None else f"{self.wavelength:g} nm"


@dataclass
class LabData:
    """Groups (one per wavelength) and the stacked values.

    ``columns``: the value columns, ``"M00"`` (1/sr, if measured) first, then the normalized
    elements; ``y``/``w``: the values and their standard deviations (None: not given), column
    by column, each over the groups; ``rows[g]``: the indices of group g's values in ``y``.
    """

    groups: list
    columns: tuple
    y: np.ndarray
    w: np.ndarray | None
    rows: list
    source: str = "<memory>"
    #: ``w`` was estimated from a fit's residuals (the file has no sigmas)
    estimated: bool = False
    #: the elements are absolute (M_jk in 1/sr, the file has M00), else normalized (M_jk/M00)
    absolute: bool = False
    #: normalized values without M00: each row's relative error of M00 (one per geometry), or None
    delta: np.ndarray | None = None
    #: ... and each value's part of its row's shared M00 noise, delta r_jk (as ``y``): r from the
    #: data, or -- ``shared_model`` -- from a fit's prediction (:meth:`with_shared`)
    shared: np.ndarray | None = None
    shared_model: bool = False
    _cache: dict = field(default_factory=dict, repr=False, compare=False)

    @property
    def has_m00(self) -> bool:
        return M00 in self.columns

    @property
    def elements(self) -> tuple:
        return tuple(c for c in self.columns if c != M00)

    @property
    def sigma_given(self) -> bool:
        """Whether the file gave sigmas (not estimated ones)."""
        return self.w is not None and not self.estimated

    @property
    def wavelengths(self) -> list:
        return [g.wavelength for g in self.groups]

    @property
    def geometries(self) -> int:
        return sum(len(g) for g in self.groups)

    def angles(self):
        """theta_i, theta_r, phi of every geometry, the groups concatenated (the residuals' order
        within one value column)."""
        return tuple(np.concatenate([getattr(g, a) for g in self.groups]) for a in ("theta_i", "theta_r", "phi"))

    def neighbours(self):
        """Each geometry's nearest geometries (:func:`hyde_bsdf.fit.adequacy.neighbour_index`), once."""
        if "neighbours" not in self._cache:
            self._cache["neighbours"] = neighbour_index(*self.angles())
        return self._cache["neighbours"]

    def column(self, values: np.ndarray, name: str, group: int) -> np.ndarray:
        """The part of a stacked vector (like ``y``) that is column ``name`` of group ``group``."""
        N = self.geometries
        c = self.columns.index(name)
        start = sum(len(g) for g in self.groups[:group])
        return values[c * N + start: c * N + start + len(self.groups[group])]

    def with_noise(self, w: np.ndarray) -> "LabData":
        """A copy with the standard deviations ``w`` (estimated ones, for data without sigmas)."""
        return replace(self, w=np.asarray(w, float), estimated=True, delta=None, shared=None, _cache={})

    def with_shared(self, prediction: np.ndarray) -> "LabData":
        """A copy whose shared noise is delta r with r a model's ``prediction`` (as ``y``): the
        measured ratios' own noise would inflate it (|r|^2 grows by ~15 delta^2 on average, and
        chi^2 fell to 0.91 of its dof at the truth)."""
        C = len(self.columns)
        shared = (self.delta * np.asarray(prediction, float).reshape(C, -1)).ravel()
        return replace(self, shared=shared, shared_model=True, _cache={})

    def whiten(self, e: np.ndarray) -> np.ndarray:
        """Residuals (as ``y``; or Jacobian columns, shape (len(y), p)) in units of their noise:
        divided by ``w``, and where rows share M00's noise (``shared``) whitened with the
        covariance diag(w^2 - shared^2) + shared shared^T of each row (module docstring)."""
        w = 1.0 if self.w is None else (self.w if e.ndim == 1 else self.w[:, None])
        if self.shared is None:
            return e / w
        if "whitening" not in self._cache:
            C, N = len(self.columns), self.geometries
            w2, s = self.w.reshape(C, N), self.shared.reshape(C, N)
            own = np.sqrt(np.maximum(w2 ** 2 - s ** 2, (0.1 * w2) ** 2))      # the elements' own noise
            u = s / own
            uu = (u * u).sum(0)
            c = np.where(uu > 1e-12, (1.0 - 1.0 / np.sqrt(1.0 + uu)) / np.maximum(uu, 1e-300), 0.5)
            self._cache["whitening"] = (own, u, c)
        own, u, c = self._cache["whitening"]
        E = e.reshape(own.shape + e.shape[1:])
        if e.ndim == 2:
            own, u, c = own[..., None], u[..., None], c[:, None]
        Et = E / own
        return (Et - c * u * (u * Et).sum(0)).reshape(e.shape)


def _group_values(meas: Measurements, keep, columns):
    """(values, sigmas or None) of the rows ``keep``: dicts column -> array, M00 included; with M00
    the elements absolute (module docstring)."""
    values = {c: (meas.m00 if c == M00 else meas.values[c])[keep] for c in columns}
    sig = None
    if meas.sigma is not None:
        unc, unc00 = meas.uncertainty(), meas.m00_uncertainty()
        sig = {c: (unc00 if c == M00 else unc[c])[keep] for c in columns}
    if meas.m00 is None:
        delta = ratio_delta(meas)
        if delta is not None:        # the weighted fit's shrinkage undone (module docstring)
            values = {c: v * (1.0 + delta[keep] ** 2) for c, v in values.items()}
        return values, sig
    m00 = values[M00]
    for c in columns[1:]:
        if sig is not None:
            r, s_r = values[c], sig[c]
            exact = (m00 * s_r) ** 2 - (r * sig[M00]) ** 2
            sig[c] = np.sqrt(np.maximum(exact, (0.1 * m00 * s_r) ** 2))
        values[c] = values[c] * m00
    return values, sig


def ratio_delta(meas: Measurements) -> np.ndarray | None:
    """Each row's relative error of M00 as its normalized sigmas imply it (module docstring), or None
    (M00 measured, or no sigmas)."""
    if meas.m00 is not None or meas.sigma is None or not meas.values:
        return None
    unc = meas.uncertainty()
    return np.median([unc[e] / np.sqrt(1.0 + meas.values[e] ** 2) for e in meas.values], axis=0)


def _informative(meas: Measurements) -> np.ndarray:
    """The rows whose normalized values carry information: all with M00 or without sigmas; else those
    whose implied relative error of M00 is at most RATIO_DELTA (module docstring)."""
    delta = ratio_delta(meas)
    return np.ones(len(meas), bool) if delta is None else delta <= RATIO_DELTA


def lab_data(meas: Measurements) -> LabData:
    """:class:`LabData` from measurements (module docstring); UsageError when there is nothing to fit."""
    if not isinstance(meas, Measurements):
        raise UsageError(f"data must be Measurements (hyde_bsdf.io.measurements.read_measurements), "
                         f"got {type(meas).__name__}")
    columns = ((M00,) if meas.m00 is not None else ()) + tuple(meas.values)
    if not columns or len(meas) == 0:
        raise UsageError(f"{meas.source}: no values to fit")
    above = (meas.theta_i < math.pi / 2) & (meas.theta_r < math.pi / 2)
    if not above.all():
        raise UsageError("theta_i and theta_r must be below 90 deg (pi/2): the model is 0 there")
    groups, ys, ws = [], [], []
    informative = _informative(meas)
    for wl in meas.wavelengths:
        keep = np.ones(len(meas), bool) if wl is None else meas.wavelength_nm == wl
        rows_in = int(keep.sum())
        keep &= informative
        if not keep.any():
            raise UsageError(f"{meas.source}: no row at {'any wavelength' if wl is None else f'{wl:g} nm'} has an M00 "
                             "known to be above 0 within 3 sigma (the normalized sigmas imply a relative error of M00 "
                             "above 1/3 in every row): the ratios carry no information -- measure M00 (1/sr)")
        values, sig = _group_values(meas, keep, columns)
        ti, tr, ph, values, sig, info = merge_repeated_geometries(
            meas.theta_i[keep], meas.theta_r[keep], meas.phi[keep], values, sig)
        groups.append(Group(wl, PreparedGeometry(ti, tr, ph), ti, tr, ph, rows_in, info,
                            rows_in - int(keep.sum())))
        ys.append(values)
        ws.append(sig)
    y = np.concatenate([ys[g][c] for c in columns for g in range(len(groups))])
    w = None if meas.sigma is None else np.concatenate([ws[g][c] for c in columns for g in range(len(groups))])
    delta = shared = None
    if meas.m00 is None and w is not None:      # the rows' shared M00 noise, delta r (module docstring)
        C = len(columns)
        r, sd = y.reshape(C, -1), w.reshape(C, -1)
        delta = np.median(sd / np.sqrt(1.0 + r ** 2), axis=0)
        shared = (delta * r).ravel()
    N = sum(len(g) for g in groups)
    rows, start = [], 0
    for g in groups:
        idx = np.arange(start, start + len(g))
        rows.append(np.concatenate([idx + c * N for c in range(len(columns))]))
        start += len(g)
    return LabData(groups, columns, y, w, rows, meas.source, absolute=meas.m00 is not None, delta=delta,
                   shared=shared)
