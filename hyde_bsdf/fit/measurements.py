"""Mueller-matrix measurement files: the CSV format ``hyde-bsdf fit`` reads.

File format
-----------
A plain comma-separated text file (UTF-8).  Lines starting with ``#`` and blank
lines are ignored anywhere.  The first other line is the header; every later
line is one measurement geometry.  Column names (exact, case-sensitive, any
order, surrounding spaces ignored):

``theta_i_deg``   polar angle of the direction towards the source, degrees in [0, 90)
``theta_r_deg``   polar angle of the direction towards the detector, degrees in [0, 90)
``phi_deg``       phi_r - phi_i in degrees, [0, 360]; 180 = the specular plane
                  (forward scattering), 0 = the backscatter side (the paper's phi)
``Mjk``           a Mueller-matrix element **normalized by M00** (M_jk / M_00, as the
                  paper plots them), j, k in 0..3, not M00 itself: ``M01``, ``M11``,
                  ``M22``, ``M23``, ...; at least one; |value| <= 1.5 (a physical
                  normalized element lies in [-1, 1]; more means an unnormalized file)
``Mjk_sigma``     its standard deviation (> 0); required for every ``Mjk`` given,
                  or for none of them (then the fit weighs all values equally and
                  estimates the noise from the scatter of the residuals)
``n_samples``     optional: number of repeated measurements each row averages (>= 1).
                  If present, ``Mjk`` are means and ``Mjk_sigma`` the standard
                  deviation of the single measurements (the paper's +-1 sigma bars
                  over 256 samples); the uncertainty of the mean, used by the fit,
                  is then ``Mjk_sigma / sqrt(n_samples)``.  If absent, ``Mjk_sigma``
                  is the uncertainty of ``Mjk`` itself.

Example (the paper's Fig. 8 geometry, specular plane theta_i = theta_r)::

    # LabSphere Infragold, 1064 nm
    theta_i_deg,theta_r_deg,phi_deg,M01,M01_sigma,M22,M22_sigma,n_samples
    10,10,180,0.0004,0.02,-0.748,0.02,256
    20,20,180,0.0011,0.02,-0.769,0.02,256

Angles are in degrees in the file and radians in :class:`Measurements`.
Malformed input raises :class:`MeasurementFileError` (a ``ValueError``) naming
the file, the line (1-based, counting comment lines) and the column.
"""
from __future__ import annotations

import csv
import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

__all__ = ["ELEMENT_NAMES", "ANGLE_COLUMNS", "MeasurementFileError", "Measurements",
           "read_measurements", "write_measurements", "element_index"]

#: normalized Mueller elements a file may hold (M00 / M00 = 1 carries no information)
ELEMENT_NAMES = tuple(f"M{j}{k}" for j in range(4) for k in range(4) if (j, k) != (0, 0))
ANGLE_COLUMNS = ("theta_i_deg", "theta_r_deg", "phi_deg")
#: accepted angle ranges in degrees: (low, high, high included?)
ANGLE_RANGES = {"theta_i_deg": (0.0, 90.0, False), "theta_r_deg": (0.0, 90.0, False),
                "phi_deg": (0.0, 360.0, True)}
#: |M_jk / M_00| <= 1 for a physical Mueller matrix; allow noise, catch unnormalized files
ELEMENT_LIMIT = 1.5


class MeasurementFileError(ValueError):
    """A measurement file that cannot be read: the message names file, line and column."""


def element_index(name: str) -> tuple[int, int]:
    """(row, column) of an element name such as ``"M23"``; ValueError for anything else."""
    if name not in ELEMENT_NAMES:
        raise ValueError(f"Mueller element name must be one of {', '.join(ELEMENT_NAMES)} "
                         f"(normalized by M00), got {name!r}")
    return int(name[1]), int(name[2])


@dataclass
class Measurements:
    """Normalized Mueller-matrix measurements at a set of geometries.

    Attributes
    ----------
    theta_i, theta_r, phi : ndarray, shape (N,), radians (the paper's angles)
    values : dict element name -> ndarray (N,), M_jk / M_00
    sigma : dict element name -> ndarray (N,) of standard deviations as written in
        the file, or None when the file has no ``*_sigma`` columns
    n_samples : ndarray (N,) or None; see the module docstring
    source : where the data came from (file name), for messages
    """

    theta_i: np.ndarray
    theta_r: np.ndarray
    phi: np.ndarray
    values: dict
    sigma: dict | None = None
    n_samples: np.ndarray | None = None
    source: str = "<memory>"
    comments: list = field(default_factory=list)

    @property
    def elements(self) -> tuple[str, ...]:
        return tuple(self.values)

    def __len__(self) -> int:
        return int(self.theta_i.size)

    def uncertainty(self) -> dict | None:
        """Standard deviation of each value as the fit should use it (sigma/sqrt(n_samples))."""
        if self.sigma is None:
            return None
        scale = 1.0 if self.n_samples is None else 1.0 / np.sqrt(self.n_samples)
        return {name: s * scale for name, s in self.sigma.items()}


def _error(path, line, column, text):
    where = f"{path}, line {line}" + (f", column {column!r}" if column else "")
    return MeasurementFileError(f"{where}: {text}")


def _number(path, line, column, cell):
    try:
        value = float(cell)
    except ValueError:
        raise _error(path, line, column, f"{cell.strip()!r} is not a number") from None
    if not math.isfinite(value):
        raise _error(path, line, column, f"{cell.strip()!r} is not a finite number")
    return value


def read_measurements(path) -> Measurements:
    """Read a measurement CSV (format: module docstring) into :class:`Measurements`.

    Raises
    ------
    MeasurementFileError (a ValueError) for a missing file, a missing/unknown/duplicate
    column, a non-numeric or non-finite cell, a row of the wrong length, an angle out of
    range, sigma <= 0, n_samples < 1 or not an integer, |M_jk| > 1.5, or no data rows.
    """
    path = Path(path)
    name = str(path)
    try:
        text = path.read_text(encoding="utf-8-sig")
    except FileNotFoundError:
        raise MeasurementFileError(f"{name}: measurement file does not exist") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise MeasurementFileError(f"{name}: cannot be read as UTF-8 text ({exc})") from None

    header = None
    rows = []          # (line number, cells)
    comments = []
    for lineno, raw in enumerate(text.splitlines(), start=1):
        stripped = raw.strip()
        if not stripped:
            continue
        if stripped.startswith("#"):
            comments.append(stripped[1:].strip())
            continue
        cells = next(csv.reader([raw]))
        if header is None:
            header = (lineno, [c.strip() for c in cells])
        else:
            rows.append((lineno, cells))
    if header is None:
        raise MeasurementFileError(f"{name}: no header line (expected columns "
                                   f"{', '.join(ANGLE_COLUMNS)}, M01, M01_sigma, ...)")
    hline, columns = header

    # ---- header: known names, no duplicates, the required ones present
    known = set(ANGLE_COLUMNS) | set(ELEMENT_NAMES) | {f"{e}_sigma" for e in ELEMENT_NAMES} | {"n_samples"}
    seen = set()
    for col in columns:
        if col not in known:
            hint = " (M00 is the normalization and is not a column)" if col.startswith("M00") else ""
            raise _error(name, hline, col, f"unknown column{hint}; accepted: "
                         f"{', '.join(ANGLE_COLUMNS)}, Mjk and Mjk_sigma for jk in "
                         f"{', '.join(e[1:] for e in ELEMENT_NAMES)}, n_samples")
        if col in seen:
            raise _error(name, hline, col, "duplicate column")
        seen.add(col)
    for col in ANGLE_COLUMNS:
        if col not in seen:
            raise _error(name, hline, None, f"missing column {col!r} (header has {', '.join(columns)})")
    elements = [c for c in columns if c in ELEMENT_NAMES]
    if not elements:
        raise _error(name, hline, None, "no Mueller element column (M01, M11, M22, M23, ...)")
    sigmas = [c for c in columns if c.endswith("_sigma")]
    for s in sigmas:
        if s[:-len("_sigma")] not in seen:
            raise _error(name, hline, s, f"sigma column without its element column {s[:-6]!r}")
    if sigmas:
        for e in elements:
            if f"{e}_sigma" not in seen:
                raise _error(name, hline, None, f"missing column {e + '_sigma'!r}: give a sigma "
                             f"column for every element, or for none")
    if not rows:
        raise MeasurementFileError(f"{name}: header but no data rows")

    # ---- cells
    index = {c: i for i, c in enumerate(columns)}
    data = {c: np.empty(len(rows)) for c in columns}
    for r, (lineno, cells) in enumerate(rows):
        if len(cells) != len(columns):
            raise _error(name, lineno, None, f"{len(cells)} cells, the header has {len(columns)} columns")
        for col, i in index.items():
            v = _number(name, lineno, col, cells[i])
            if col in ANGLE_RANGES:
                lo, hi, closed = ANGLE_RANGES[col]
                if v < lo or v > hi or (v == hi and not closed):
                    rng = f"[{lo:g}, {hi:g}{']' if closed else ')'}"
                    raise _error(name, lineno, col, f"angle {v:g} deg is out of range {rng} degrees")
            elif col.endswith("_sigma"):
                if v <= 0.0:
                    raise _error(name, lineno, col, f"standard deviation must be > 0, got {v:g}")
            elif col == "n_samples":
                if v < 1 or v != int(v):
                    raise _error(name, lineno, col, f"n_samples must be an integer >= 1, got {v:g}")
            elif abs(v) > ELEMENT_LIMIT:
                raise _error(name, lineno, col, f"{v:g} is not a normalized element (|M_jk/M_00| <= 1 "
                             f"for a physical Mueller matrix): divide the elements by M00")
            data[col][r] = v

    return Measurements(
        theta_i=np.radians(data["theta_i_deg"]),
        theta_r=np.radians(data["theta_r_deg"]),
        phi=np.radians(data["phi_deg"]),
        values={e: data[e] for e in elements},
        sigma={e: data[f"{e}_sigma"] for e in elements} if sigmas else None,
        n_samples=data.get("n_samples"),
        source=name,
        comments=comments,
    )


def write_measurements(path, meas: Measurements, comments=()) -> Path:
    """Write ``meas`` in the format :func:`read_measurements` reads (angles in degrees)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    cols = list(ANGLE_COLUMNS)
    arrays = [np.degrees(meas.theta_i), np.degrees(meas.theta_r), np.degrees(meas.phi)]
    for e, v in meas.values.items():
        element_index(e)
        cols.append(e)
        arrays.append(np.asarray(v, float))
        if meas.sigma is not None:
            cols.append(f"{e}_sigma")
            arrays.append(np.asarray(meas.sigma[e], float))
    if meas.n_samples is not None:
        cols.append("n_samples")
        arrays.append(np.asarray(meas.n_samples, float))
    with path.open("w", newline="", encoding="utf-8") as fh:
        for c in list(comments) + list(meas.comments):
            fh.write(f"# {c}\n")
        w = csv.writer(fh, lineterminator="\n")
        w.writerow(cols)
        for row in zip(*arrays):
            w.writerow([f"{x:.10g}" if c != "n_samples" else str(int(x)) for c, x in zip(cols, row)])
    return path
