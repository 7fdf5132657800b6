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
``Mjk_sigma``     its standard deviation, in [1e-12, 1e3]; required for every ``Mjk`` given,
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

Every cell is a plain decimal number (``-0.75``, ``1e-3``); Python spellings such as
``1_0``, ``inf`` or ``nan`` are refused.  Angles are in degrees in the file and radians in
:class:`Measurements`.
Malformed input raises :class:`MeasurementFileError` (a ``ValueError``) naming
the file, the line (1-based, counting comment lines) and the column.
"""
from __future__ import annotations

import csv
import io
import re
import time
import warnings
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from hyde_bsdf.errors import InputFileError, UsageError
from hyde_bsdf.io.atomic import atomic_open
from hyde_bsdf.io.input_gate import STDIN, check_input, csv_rows, read_input
from hyde_bsdf.io.output_gate import check_output_path
from hyde_bsdf.progress import as_callback

__all__ = ["ELEMENT_NAMES", "ANGLE_COLUMNS", "SIGMA_RANGE", "ELEMENT_LIMIT", "MeasurementFileError", "Measurements",
           "read_measurements", "write_measurements", "element_index"]

#: normalized Mueller elements a file may hold (M00 / M00 = 1 carries no information)
ELEMENT_NAMES = tuple(f"M{j}{k}" for j in range(4) for k in range(4) if (j, k) != (0, 0))
ANGLE_COLUMNS = ("theta_i_deg", "theta_r_deg", "phi_deg")
#: accepted angle ranges in degrees: (low, high, high included?)
ANGLE_RANGES = {"theta_i_deg": (0.0, 90.0, False), "theta_r_deg": (0.0, 90.0, False),
                "phi_deg": (0.0, 360.0, True)}
#: |M_jk / M_00| <= 1 for a physical Mueller matrix; allow noise, catch unnormalized files
ELEMENT_LIMIT = 1.5
#: accepted standard deviations of a normalized element: below 1e-12 the weighted residuals
#: (up to 3 / sigma) and their squares leave the range where the least-squares solver works
SIGMA_RANGE = (1e-12, 1e3)


class MeasurementFileError(InputFileError):
    """A measurement file that cannot be read: the message names file, line and column."""


def _cells(name, lineno, line: str) -> list:
    """The CSV cells of one line, through the input gate's field limit (a huge cell: one line)."""
    try:
        rows = csv_rows(line, f"{name}, line {lineno}")
    except UsageError as exc:
        raise MeasurementFileError(str(exc).replace(": row 1:", ":")) from None
    return rows[0] if rows else [""]


def element_index(name: str) -> tuple[int, int]:
    """(row, column) of an element name such as ``"M23"``; ValueError for anything else."""
    if name not in ELEMENT_NAMES:
        raise UsageError(f"Mueller element name must be one of {', '.join(ELEMENT_NAMES)} "
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


#: a decimal number as the format accepts it: digits, one point, an exponent; nothing else.
#: (Python's float() also takes "1_0" = 10, "infinity", non-ASCII digits: all refused here.)
_NUMBER = re.compile(r"[ \t]*[+-]?(?:[0-9]+\.?[0-9]*|\.[0-9]+)(?:[eE][+-]?[0-9]+)?[ \t]*\Z")
_NON_FINITE = re.compile(r"[ \t]*[+-]?(?:nan|inf|infinity)[ \t]*\Z", re.IGNORECASE)


def _number(path, line, column, cell):
    if _NUMBER.match(cell):
        return float(cell)
    if _NON_FINITE.match(cell):
        raise _error(path, line, column, f"{cell.strip()!r} is not a finite number")
    hint = " (no digit separators)" if "_" in cell else ""
    raise _error(path, line, column, f"{cell.strip()!r} is not a number{hint}")


_PLAIN = b"0123456789eE.+-, \t\r\n"


def _plain_block(body: bytes) -> bool:
    """Only digits, signs, points, exponents, commas and whitespace; CR only in CRLF.
    (bytes.translate and count run at memory speed; a regex took 1.5 s per 100 MB.)"""
    return not body.translate(None, _PLAIN) and body.count(b"\r") == body.count(b"\r\n")


_BOMS = ((b"\xff\xfe\x00\x00", "utf-32"), (b"\x00\x00\xfe\xff", "utf-32"),
         (b"\xff\xfe", "utf-16"), (b"\xfe\xff", "utf-16"))


def _normalise(name, raw: bytes) -> bytes:
    """UTF-8 bytes with LF line ends, whatever the file had: a UTF-16/32 byte-order mark (a
    spreadsheet's "Unicode text") is decoded, a UTF-8 one dropped, and CRLF (Windows) and lone
    CR (classic Mac OS) line ends become LF -- so every later step sees one kind of text."""
    for bom, codec in _BOMS:
        if raw.startswith(bom):
            try:
                raw = raw.decode(codec).encode("utf-8")
            except UnicodeError as exc:
                raise MeasurementFileError(f"{name}: cannot be read as {codec.upper()} text ({exc})") from None
            break
    if raw.startswith(b"\xef\xbb\xbf"):
        raw = raw[3:]
    if b"\r" in raw:
        raw = raw.replace(b"\r\n", b"\n").replace(b"\r", b"\n")
    return raw


def _decode(name, raw: bytes) -> str:
    try:
        return raw.decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        raise MeasurementFileError(f"{name}: cannot be read as UTF-8 text ({exc})") from None


def _skipped(line: str, comments: list) -> bool:
    """Whether ``line`` is blank or a comment (a comment's text is added to ``comments``)."""
    stripped = line.strip()
    if stripped and stripped[0] == "#":
        comments.append(stripped[1:].strip())
    return not stripped or stripped[0] == "#"


def _split_header(name, raw: bytes):
    """((line number, column names), the bytes after the header line, comments before it)."""
    comments = []
    pos, lineno = 0, 0
    while pos < len(raw):
        end = raw.find(b"\n", pos)
        end = len(raw) if end < 0 else end
        line = _decode(name, raw[pos:end])     # line ends are LF only here (_normalise)
        lineno += 1
        pos = end + 1
        if _skipped(line, comments):
            continue
        return (lineno, [c.strip() for c in _cells(name, lineno, line)]), raw[pos:], comments
    raise MeasurementFileError(f"{name}: no header line (expected columns "
                               f"{', '.join(ANGLE_COLUMNS)}, M01, M01_sigma, ...)")


def _data_lines(name, raw: bytes, hline: int, comments: list):
    """The data lines after the header, with their 1-based numbers (comments collected)."""
    linenos, lines = [], []
    for lineno, line in enumerate(_decode(name, raw).split("\n"), start=1):
        if lineno <= hline:
            continue
        if _skipped(line, comments):
            continue
        linenos.append(lineno)
        lines.append(line)
    return linenos, lines


def _parse_fast(body: bytes, rows: int, ncols: int):
    """NumPy's C parser on a block of plain numbers; None if it does not parse cleanly."""
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            data = np.loadtxt(io.BytesIO(body), delimiter=",", dtype=float, ndmin=2, comments=None,
                              encoding="ascii")
    except ValueError:
        return None
    return data if data.shape == (rows, ncols) else None


def _parse_careful(name, columns, linenos, lines):
    """Cell by cell, with the csv module (quotes allowed): the first bad cell is reported."""
    data = np.empty((len(lines), len(columns)))
    for r, (lineno, raw) in enumerate(zip(linenos, lines)):
        cells = _cells(name, lineno, raw)
        if len(cells) != len(columns):
            raise _error(name, lineno, None, f"{len(cells)} cells, the header has {len(columns)} columns")
        for i, col in enumerate(columns):
            data[r, i] = _number(name, lineno, col, cells[i])
    return data


def _parse(name, columns, linenos, lines):
    """The data block as an (rows, columns) array: NumPy's parser when the block holds only
    plain numbers and commas (fast: 10^6 rows in about a second), else the careful path,
    which also pinpoints the cell the fast parser stumbled on."""
    block = "\n".join(lines)
    if _plain_block(block.encode("utf-8")):
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")       # "empty input" and similar
                data = np.loadtxt(io.StringIO(block), delimiter=",", dtype=float, ndmin=2,
                                  comments=None)
            if data.shape == (len(lines), len(columns)):
                return data
        except ValueError:
            pass
    return _parse_careful(name, columns, linenos, lines)


def _check_values(name, columns, linenos, data):
    """Range checks on the whole array at once; the first offending cell (row, then column
    order, as a reader going through the file would meet it) is reported."""
    first = None                                   # (row, column index, message)
    for i, col in enumerate(columns):
        v = data[:, i]
        if col in ANGLE_RANGES:
            lo, hi, closed = ANGLE_RANGES[col]
            bad = (v < lo) | (v > hi) | ((v == hi) if not closed else False)
            rng = f"[{lo:g}, {hi:g}{']' if closed else ')'}"
            text = lambda x, rng=rng: f"angle {x:g} deg is out of range {rng} degrees"
        elif col.endswith("_sigma"):
            bad = ~((v >= SIGMA_RANGE[0]) & (v <= SIGMA_RANGE[1]))
            text = lambda x: (f"standard deviation must be > 0, got {x:g}" if x <= 0 else
                              f"standard deviation {x:g} is outside the accepted range "
                              f"[{SIGMA_RANGE[0]:g}, {SIGMA_RANGE[1]:g}]")
        elif col == "n_samples":
            bad = (v < 1) | (v != np.floor(v)) | (v > 1e12)
            text = lambda x: f"n_samples must be an integer in [1, 1e12], got {x:g}"
        else:
            bad = ~(np.abs(v) <= ELEMENT_LIMIT)
            text = lambda x: (f"{x:g} is not a normalized element (|M_jk/M_00| <= 1 for a physical "
                              f"Mueller matrix): divide the elements by M00")
        if bad.any():
            r = int(np.argmax(bad))
            if first is None or r < first[0]:
                first = (r, col, text(v[r]))
    if first is not None:
        r, col, msg = first
        raise _error(name, int(linenos[r]), col, msg)


def read_measurements(path, progress=None) -> Measurements:
    """Read a measurement CSV (format: module docstring) into :class:`Measurements`.

    ``progress``: a callback told about reading a large file (> 10 MB); True for lines on stderr
    (:mod:`hyde_bsdf.progress`).

    Raises
    ------
    MeasurementFileError (a ValueError) for a missing file, a missing/unknown/duplicate
    column, a cell that is not a plain decimal number (``1_0``, ``0x10``, ``ten``) or not finite,
    a row of the wrong length, an angle out of range, sigma outside [1e-12, 1e3], n_samples
    < 1 or not an integer, |M_jk| > 1.5, or no data rows.  The message names the file, the
    line (1-based, counting comment lines) and the column.
    """
    t0 = time.perf_counter()
    report = as_callback(progress)
    path = Path(path)
    name = str(path)
    raw, size = _read_gated(path, name, report)
    raw = _normalise(name, raw)
    header, body, comments = _split_header(name, raw)
    hline, columns = header
    # the common case -- after the header only lines of plain numbers, no comments or blank
    # lines -- goes straight to NumPy's parser; anything else through the line-by-line path
    table = linenos = None
    body = body.rstrip()
    if body and _plain_block(body):          # blank lines make the row count differ: careful path
        rows = body.count(b"\n") + 1
        table = _parse_fast(body, rows, len(columns))
        if table is not None:
            linenos = np.arange(hline + 1, hline + 1 + rows)
    if table is None:
        linenos, lines = _data_lines(name, raw, hline, comments)
    elements, sigmas = _check_columns(name, hline, columns)
    if table is None:
        if not lines:
            raise MeasurementFileError(f"{name}: header but no data rows")
        table = _parse(name, columns, linenos, lines)
        del lines
        linenos = np.asarray(linenos)
    del raw, body
    _check_values(name, columns, linenos, table)
    table = np.ascontiguousarray(table.T)          # one copy: each column contiguous
    data = dict(zip(columns, table))
    if report and size > 10e6:
        report(f"read {len(linenos)} rows in {time.perf_counter() - t0:.1f} s")

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


def _read_gated(path, name, report):
    """The file's bytes through the input gate (a regular file or stdin, size-limited, read once;
    no FIFO, no device), and its size (0 for stdin)."""
    try:
        checked = check_input(path, "measurement file")
        size = 0 if checked == STDIN else checked.stat().st_size
        if report and size > 10e6:
            report(f"reading {name} ({size / 1e6:.0f} MB)")
        return read_input(path, "measurement file"), size
    except UsageError as exc:
        raise MeasurementFileError(str(exc)) from None


def _check_columns(name, hline, columns):
    """The header: known names, no duplicates, the required ones present, a sigma column for
    every element or for none.  Returns (element columns, sigma columns)."""
    known = set(ANGLE_COLUMNS) | set(ELEMENT_NAMES) | {f"{e}_sigma" for e in ELEMENT_NAMES} | {"n_samples"}
    seen = set()
    for col in columns:
        if col not in known:
            hint = " (M00 is the normalization and is not a column)" if col.startswith("M00") else ""
            for sep, word in ((";", "semicolons"), ("\t", "tabs")):
                if sep in col and "," not in col:
                    hint = f" (the columns are separated by {word}; this format uses commas)"
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
    return elements, sigmas


def write_measurements(path, meas: Measurements, comments=()) -> Path:
    """Write ``meas`` in the format :func:`read_measurements` reads (angles in degrees).

    The file appears complete or not at all (:mod:`hyde_bsdf.io.atomic`); ValueError naming the
    path if it cannot be written."""
    path = check_output_path(path, "measurement file")
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
    with atomic_open(path, "w", newline="", encoding="utf-8") as fh:
        for c in list(comments) + list(meas.comments):
            fh.write(f"# {c}\n")
        w = csv.writer(fh, lineterminator="\n")
        w.writerow(cols)
        for row in zip(*arrays):
            w.writerow([f"{x:.10g}" if c != "n_samples" else str(int(x)) for c, x in zip(cols, row)])
    return path
