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
                  (forward scattering), 0 = the backscatter side (the paper's phi) ...
``phi_i_deg``, ``phi_r_deg``  ... or, instead of ``phi_deg``, the azimuths of the source and the
                  detector as a goniometer reports them, each in [-360, 360]; phi = phi_r - phi_i
                  (an isotropic surface depends on their difference only).  Any geometry, in or
                  out of the plane of incidence, is one row.
``M00``           optional: the BRDF itself, M_00 in 1/sr (what a scatterometer measures: its
                  height and lobe width carry the roughness; a fit without it sees the roughness
                  only through the size of the diffuse part)
``Mjk``           a Mueller-matrix element **normalized by M00** (M_jk / M_00, as the
                  paper plots them), j, k in 0..3: ``M01``, ``M11``, ``M22``, ``M23``, ...
                  At least one of ``M00`` and the ``Mjk``.
``Mjk_sigma``, ``M00_sigma``  the standard deviation of each value (M00's in 1/sr), in
                  [1e-12, 1e3]; required for every value column given, or for none of them
                  (then the fit estimates the noise from the scatter of the residuals)
``n_samples``     optional: number of repeated measurements each row averages (>= 1).
                  If present, the values are means and the ``*_sigma`` the standard
                  deviation of the single measurements (the paper's +-1 sigma bars
                  over 256 samples); the uncertainty of the mean, used by the fit,
                  is then ``sigma / sqrt(n_samples)``.  If absent, ``*_sigma``
                  is the uncertainty of the value itself.
``wavelength_nm`` optional: the wavelength of each row in nm, in [10, 1e6]; rows at several
                  wavelengths in one file are fitted jointly (one roughness, an index per
                  wavelength).

Values outside the physical range are judged against their own uncertainty: |M_jk/M_00| <= 1
and M00 >= 0 hold for every physical measurement, and a value within 3 standard deviations of
that range -- or within what the noise of a file of that many values reaches with probability
0.001, if more (:func:`impossible_limit`: 4.8 sigma for 10^3 values) -- is data, kept as it
is (the fit flags a degree of polarization above 1 beyond the same limit).  Only a value that is impossible at its stated error
is refused, naming its line.  Without sigma columns a normalized element must satisfy
|M_jk/M_00| <= 1.5 (more means an unnormalized file) and M00 >= 0.

Example (the paper's Fig. 8 geometry, specular plane theta_i = theta_r)::

    # LabSphere Infragold, 1064 nm
    theta_i_deg,theta_r_deg,phi_deg,M01,M01_sigma,M22,M22_sigma,n_samples
    10,10,180,0.0004,0.02,-0.748,0.02,256
    20,20,180,0.0011,0.02,-0.769,0.02,256

With M00 (1/sr) at two wavelengths, out of the plane, azimuths as the goniometer gives them::

    wavelength_nm,theta_i_deg,theta_r_deg,phi_i_deg,phi_r_deg,M00,M00_sigma,M22,M22_sigma
    632.8,30,30,0,180,2.31,0.025,-0.81,0.012
    1550,30,45,0,120,0.58,0.008,-0.32,0.02

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

from hyde_bsdf.errors import InputFileError, UsageError, shorten
from hyde_bsdf.io.atomic import atomic_open
from hyde_bsdf.io.input_gate import STDIN, check_csv_values, check_input, csv_rows, read_input
from hyde_bsdf.io.output_gate import check_output_path
from hyde_bsdf.progress import as_callback

__all__ = ["ELEMENT_NAMES", "ANGLE_COLUMNS", "AZIMUTH_COLUMNS", "M00", "WAVELENGTH", "WAVELENGTH_RANGE", "SIGMA_RANGE",
           "ELEMENT_LIMIT", "MeasurementFileError", "Measurements", "impossible_limit", "read_measurements",
           "write_measurements", "element_index"]

#: normalized Mueller elements a file may hold (M00 / M00 = 1 carries no information)
ELEMENT_NAMES = tuple(f"M{j}{k}" for j in range(4) for k in range(4) if (j, k) != (0, 0))
ANGLE_COLUMNS = ("theta_i_deg", "theta_r_deg", "phi_deg")
#: the goniometer's spelling of phi_deg: both azimuths (phi = phi_r - phi_i)
AZIMUTH_COLUMNS = ("phi_i_deg", "phi_r_deg")
#: the BRDF itself (1/sr), and the wavelength column (nm)
M00 = "M00"
WAVELENGTH = "wavelength_nm"
#: accepted wavelengths in nm (extreme UV to far infrared)
WAVELENGTH_RANGE = (10.0, 1e6)
#: accepted angle ranges in degrees: (low, high, high included?)
ANGLE_RANGES = {"theta_i_deg": (0.0, 90.0, False), "theta_r_deg": (0.0, 90.0, False),
                "phi_deg": (0.0, 360.0, True), "phi_i_deg": (-360.0, 360.0, True),
                "phi_r_deg": (-360.0, 360.0, True)}
#: without sigmas: |M_jk / M_00| <= 1 for a physical Mueller matrix; allow noise, catch unnormalized files
ELEMENT_LIMIT = 1.5
#: a value within this many standard deviations of its physical range is data (at least)
IMPOSSIBLE_SIGMAS = 3.0
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


def impossible_limit(count: int) -> float:
    """How many standard deviations beyond its physical range a value must lie to be refused as
    impossible: 3, or the excess that Gaussian noise reaches in one of ``count`` values with
    probability 0.001 if that is more (4.8 for 10^3 values, 6.0 for 10^6), so that a file of
    honest measurements at the edge of the range (M11 of a mirror, M00 of a dark lobe) is refused
    by chance once in a thousand files, whatever its size."""
    from statistics import NormalDist

    return max(IMPOSSIBLE_SIGMAS, NormalDist().inv_cdf(1.0 - 1e-3 / max(int(count), 1)))


def element_index(name: str) -> tuple[int, int]:
    """(row, column) of an element name such as ``"M23"``; ValueError for anything else."""
    if name not in ELEMENT_NAMES:
        raise UsageError(f"Mueller element name must be one of {', '.join(ELEMENT_NAMES)} "
                         f"(normalized by M00), got {name!r}")
    return int(name[1]), int(name[2])


@dataclass
class Measurements:
    """Mueller-matrix measurements at a set of geometries (and wavelengths).

    Attributes
    ----------
    theta_i, theta_r, phi : ndarray, shape (N,), radians (the paper's angles)
    values : dict element name -> ndarray (N,), M_jk / M_00 (normalized; may be empty when
        ``m00`` is given)
    sigma : dict element name -> ndarray (N,) of standard deviations as written in
        the file, or None when the file has no ``*_sigma`` columns
    n_samples : ndarray (N,) or None; see the module docstring
    source : where the data came from (file name), for messages
    m00 : ndarray (N,) or None: the BRDF M_00 in 1/sr
    m00_sigma : ndarray (N,) or None: its standard deviation as written (1/sr)
    wavelength_nm : ndarray (N,) or None: each row's wavelength (None: one, unstated)
    """

    theta_i: np.ndarray
    theta_r: np.ndarray
    phi: np.ndarray
    values: dict
    sigma: dict | None = None
    n_samples: np.ndarray | None = None
    source: str = "<memory>"
    comments: list = field(default_factory=list)
    m00: np.ndarray | None = None
    m00_sigma: np.ndarray | None = None
    wavelength_nm: np.ndarray | None = None

    @property
    def elements(self) -> tuple[str, ...]:
        return tuple(self.values)

    @property
    def wavelengths(self) -> tuple:
        """The distinct wavelengths (nm, ascending), or ``(None,)`` without a wavelength column."""
        if self.wavelength_nm is None:
            return (None,)
        return tuple(float(w) for w in np.unique(self.wavelength_nm))

    def __len__(self) -> int:
        return int(self.theta_i.size)

    def _mean_scale(self):
        return 1.0 if self.n_samples is None else 1.0 / np.sqrt(self.n_samples)

    def uncertainty(self) -> dict | None:
        """Standard deviation of each normalized value as the fit should use it (sigma/sqrt(n_samples))."""
        if self.sigma is None:
            return None
        scale = self._mean_scale()
        return {name: s * scale for name, s in self.sigma.items()}

    def m00_uncertainty(self) -> np.ndarray | None:
        """Standard deviation of M00 (1/sr) as the fit should use it (sigma/sqrt(n_samples))."""
        return None if self.m00_sigma is None else self.m00_sigma * self._mean_scale()

    def rows(self, keep) -> "Measurements":
        """The measurements of the rows ``keep`` (a boolean mask or indices)."""
        cut = lambda a: None if a is None else np.asarray(a)[keep]
        return Measurements(theta_i=cut(self.theta_i), theta_r=cut(self.theta_r), phi=cut(self.phi),
                            values={e: cut(v) for e, v in self.values.items()},
                            sigma=None if self.sigma is None else {e: cut(v) for e, v in self.sigma.items()},
                            n_samples=cut(self.n_samples), source=self.source, comments=list(self.comments),
                            m00=cut(self.m00), m00_sigma=cut(self.m00_sigma), wavelength_nm=cut(self.wavelength_nm))


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


def _first_bad(first, r, col, message):
    """The earlier (row, column order) of ``first`` and the offending cell (r, col, message)."""
    return (r, col, message) if first is None or r < first[0] else first


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
        elif col == WAVELENGTH:
            bad = ~((v >= WAVELENGTH_RANGE[0]) & (v <= WAVELENGTH_RANGE[1]))
            text = lambda x: (f"wavelength {x:g} nm is outside the accepted range "
                              f"[{WAVELENGTH_RANGE[0]:g}, {WAVELENGTH_RANGE[1]:g}] nm")
        else:
            continue                               # values: judged against their sigmas below
        if bad.any():
            r = int(np.argmax(bad))
            first = _first_bad(first, r, col, text(v[r]))
    if first is None:
        first = _check_physical(columns, data)
    if first is not None:
        r, col, msg = first
        raise _error(name, int(linenos[r]), col, msg)


def _check_physical(columns, data):
    """The first value impossible at its stated error (module docstring), as (row, column, message),
    or None.  Run after the sigma and n_samples columns are known to be valid."""
    index = {c: i for i, c in enumerate(columns)}
    sigmas = any(c.endswith("_sigma") for c in columns)
    scale = 1.0 / np.sqrt(data[:, index["n_samples"]]) if "n_samples" in index else 1.0
    elements = [c for c in columns if c in ELEMENT_NAMES]
    limit = impossible_limit(data.shape[0] * max(len(elements) + (M00 in index), 1))
    first = None
    for col in elements + ([M00] if M00 in index else []):
        v = data[:, index[col]]
        u = data[:, index[col + "_sigma"]] * scale if sigmas else None
        if col == M00:
            excess = -v if u is None else -v / u
            bad = excess > (0.0 if u is None else limit)
            text = lambda r: (f"M00 = {v[r]:g} 1/sr is negative" + (
                "" if u is None else f", {excess[r]:.3g} standard deviations ({u[r]:.3g}) below 0 (values within "
                f"{limit:.3g} are kept as data)") + ": a BRDF is >= 0; check the background subtraction or the sigma")
        else:
            excess = np.abs(v) - (ELEMENT_LIMIT if u is None else 1.0)
            excess = excess if u is None else excess / u
            bad = excess > (0.0 if u is None else limit)
            text = lambda r: (f"{v[r]:g} is not a normalized element (|M_jk/M_00| <= 1 for a physical Mueller matrix"
                              + ("" if u is None else f"; it lies {excess[r]:.3g} standard deviations ({u[r]:.3g}) "
                                 f"beyond, and values within {limit:.3g} are kept as data") +
                              "): divide the elements by M00" + ("" if u is None else ", or check the sigma"))
        if bad.any():
            r = int(np.argmax(bad))
            first = _first_bad(first, r, col, text(r))
    if first is None and M00 in index and np.all(data[:, index[M00]] == 1.0) and data.shape[0] > 1:
        first = (0, M00, "M00 is 1 in every row: that is M00/M00, not the BRDF; give the measured M00 in 1/sr, "
                 "or drop the column (the normalized elements alone are a valid file)")
    return first


def read_measurements(path, progress=None) -> Measurements:
    """Read a measurement CSV (format: module docstring) into :class:`Measurements`.

    ``progress``: a callback told about reading a large file (> 10 MB); True for lines on stderr
    (:mod:`hyde_bsdf.progress`).

    Raises
    ------
    MeasurementFileError (a ValueError) for a missing file, a missing/unknown/duplicate
    column, a cell that is not a plain decimal number (``1_0``, ``0x10``, ``ten``) or not finite,
    a row of the wrong length, an angle or a wavelength out of range, sigma outside [1e-12, 1e3],
    n_samples < 1 or not an integer, a value impossible at its stated error (|M_jk/M_00| > 1 or
    M00 < 0 beyond :func:`impossible_limit` standard deviations; without sigmas |M_jk| > 1.5 or
    M00 < 0), or no data rows.  The message names the file, the line (1-based, counting comment
    lines) and the column.
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

    if "phi_deg" in data:
        phi = np.radians(data["phi_deg"])
    else:      # the goniometer's azimuths: only their difference matters (isotropic surface)
        phi = np.radians(np.mod(data["phi_r_deg"] - data["phi_i_deg"], 360.0))
    return Measurements(
        theta_i=np.radians(data["theta_i_deg"]),
        theta_r=np.radians(data["theta_r_deg"]),
        phi=phi,
        values={e: data[e] for e in elements},
        sigma={e: data[f"{e}_sigma"] for e in elements} if sigmas else None,
        n_samples=data.get("n_samples"),
        source=name,
        comments=comments,
        m00=data.get(M00),
        m00_sigma=data.get(M00 + "_sigma") if sigmas else None,
        wavelength_nm=data.get(WAVELENGTH),
    )


def _read_gated(path, name, report):
    """The file's bytes through the input gate (a regular file or stdin, size-limited, read once;
    no FIFO, no device), and its size (0 for stdin)."""
    try:
        checked = check_input(path, "measurement file")
        size = 0 if checked == STDIN else checked.stat().st_size
        if report and size > 10e6:
            report(f"reading {name} ({size / 1e6:.0f} MB)")
        raw = read_input(path, "measurement file")
        check_csv_values(raw, f"measurement file {shorten(name)}")      # before it is decoded
        return raw, size
    except UsageError as exc:
        raise MeasurementFileError(str(exc)) from None


_VALUE_NAMES = (M00,) + ELEMENT_NAMES
_KNOWN = (set(ANGLE_COLUMNS) | set(AZIMUTH_COLUMNS) | set(_VALUE_NAMES) | {f"{e}_sigma" for e in _VALUE_NAMES}
          | {"n_samples", WAVELENGTH})


def _check_columns(name, hline, columns):
    """The header: known names, no duplicates, the required ones present, a sigma column for
    every value column or for none.  Returns (normalized element columns, sigma columns)."""
    seen = set()
    for col in columns:
        if col not in _KNOWN:
            hint = ""
            for sep, word in ((";", "semicolons"), ("\t", "tabs")):
                if sep in col and "," not in col:
                    hint = f" (the columns are separated by {word}; this format uses commas)"
            raise _error(name, hline, col, f"unknown column{hint}; accepted: theta_i_deg, theta_r_deg, phi_deg (or "
                         f"phi_i_deg and phi_r_deg), M00 (1/sr), Mjk (normalized by M00) for jk in "
                         f"{', '.join(e[1:] for e in ELEMENT_NAMES)}, their *_sigma, n_samples, {WAVELENGTH}")
        if col in seen:
            raise _error(name, hline, col, "duplicate column")
        seen.add(col)
    for col in ANGLE_COLUMNS[:2]:
        if col not in seen:
            raise _error(name, hline, None, f"missing column {col!r} (header has {', '.join(columns)})")
    azimuths = [c for c in AZIMUTH_COLUMNS if c in seen]
    if "phi_deg" in seen and azimuths:
        raise _error(name, hline, azimuths[0], "give phi_deg (= phi_r - phi_i) or phi_i_deg and phi_r_deg, not both")
    if "phi_deg" not in seen and len(azimuths) != 2:
        missing = "phi_deg" if not azimuths else next(c for c in AZIMUTH_COLUMNS if c not in seen)
        raise _error(name, hline, None, f"missing column {missing!r} (header has {', '.join(columns)})")
    elements = [c for c in columns if c in ELEMENT_NAMES]
    if not elements and M00 not in seen:
        raise _error(name, hline, None, "no Mueller element column (M00, M01, M11, M22, M23, ...)")
    sigmas = [c for c in columns if c.endswith("_sigma")]
    for s in sigmas:
        if s[:-len("_sigma")] not in seen:
            raise _error(name, hline, s, f"sigma column without its element column {s[:-6]!r}")
    if sigmas:
        for e in elements + ([M00] if M00 in seen else []):
            if f"{e}_sigma" not in seen:
                raise _error(name, hline, None, f"missing column {e + '_sigma'!r}: give a sigma "
                             f"column for every value column, or for none")
    return elements, sigmas


def write_measurements(path, meas: Measurements, comments=()) -> Path:
    """Write ``meas`` in the format :func:`read_measurements` reads (angles in degrees).

    The file appears complete or not at all (:mod:`hyde_bsdf.io.atomic`); ValueError naming the
    path if it cannot be written."""
    path = check_output_path(path, "measurement file")
    cols, arrays = [], []
    if meas.wavelength_nm is not None:
        cols.append(WAVELENGTH)
        arrays.append(np.asarray(meas.wavelength_nm, float))
    cols += list(ANGLE_COLUMNS)
    arrays += [np.degrees(meas.theta_i), np.degrees(meas.theta_r), np.degrees(np.mod(meas.phi, 2 * np.pi))]
    if meas.m00 is not None:
        cols.append(M00)
        arrays.append(np.asarray(meas.m00, float))
        if meas.sigma is not None or meas.m00_sigma is not None:
            cols.append(M00 + "_sigma")
            arrays.append(np.asarray(meas.m00_sigma, float))
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
