"""Measured pBRDF tables in the format of Mitsuba's ``measured_polarized`` plugin (``.pbsdf``).

The format (Mitsuba 3.9 ``src/bsdfs/measured_polarized.cpp``; Baek et al. 2020, the KAIST
database) is a Mitsuba ``TensorFile`` with these fields:

=========== ======== ===================================== =====================================
field       dtype    shape                                 meaning
=========== ======== ===================================== =====================================
``theta_h`` float32  (1, N_th)                             half-vector polar angle, radians
``theta_d`` float32  (1, N_td)                             difference angle, radians
``phi_d``   float32  (1, N_pd)                             difference azimuth, radians, [-pi, pi]
``wvls``    uint16   (K,)                                  band wavelengths, nm (K = 5)
``M``       float32  (N_pd, N_td, N_th, K, 4, 4)           Mueller BRDF, 1/sr (not times cos)
=========== ======== ===================================== =====================================

Other fields are ignored by Mitsuba (the exporter stores its provenance in ``hyde_export``).

Geometry and frames (as the C++ ``eval``; in Radiance mode ``wo`` points to the light, the
paper's omega_i, and ``si.wi`` to the observer, omega_r):

- isotropic Rusinkiewicz coordinates: h = normalize(omega_i + omega_r), theta_h = angle(n, h),
  theta_d = angle(h, omega_i), phi_d = atan2(b . i', t . i') with b = normalize(n x h),
  t = normalize(b x h) and i' the part of omega_i normal to h.  Conversely, with h in the
  x-z plane: omega_i = cos theta_d h + sin theta_d (cos phi_d t + sin phi_d b) and omega_r
  its mirror image about h (:func:`rusinkiewicz_to_directions`);
- both Stokes frames have x = normalize(omega_i x omega_r) (= Mitsuba's ``wo x wi``,
  roughconductor's s axis) and y = k x x for the propagation direction k (-omega_i in,
  +omega_r out) -- not the paper's per-wave s = k x z.  :func:`hyde_bsdf.fit.pbsdf_samples.table_to_paper` and
  :func:`~hyde_bsdf.fit.pbsdf_samples.paper_to_table` rotate a Mueller matrix between the two (S3 has the same sign in both);
- ``M`` is the BRDF itself (1/sr); Mitsuba's ``eval`` multiplies it by cos theta.

Loader quirks (measured with Mitsuba 3.9.1): it copies exactly 5 wavelengths and clamps
queries outside them (450-650 nm in the KAIST files); interpolation is multilinear in
(phi_d, theta_d, theta_h, wavelength), so a NaN at any of the 16 corners is NaN in the result:
in M00 (at any of the spectral samples) the whole matrix is zeroed, in any other element it
stays and the frame rotation spreads it over the whole matrix (a NaN pixel); theta_h = 0 exactly
gives NaN coordinates, so 0; omega_i = omega_r gives NaN frames, so NaN in every element the
rotation touches.  :meth:`PbsdfTable.interpolate` reproduces the lookup in NumPy.

Angles in the paper's terms, cell classification and subsampling for fitting are in
:mod:`hyde_bsdf.fit.pbsdf_samples`.

The reader and writer are plain NumPy (``M`` is memory-mapped, so a 1 GB file is subsampled
without loading it); Mitsuba is not needed.  Writing (:func:`write_pbsdf`) is atomic
(:mod:`hyde_bsdf.io.atomic`) and streams ``M`` slab by slab.
"""
from __future__ import annotations

import json
import math
import struct
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from hyde_bsdf.io.atomic import atomic_path
from hyde_bsdf.errors import InputFileError, UsageError, shorten
from hyde_bsdf.io.input_gate import check_dimensions, check_input
from hyde_bsdf.io.output_gate import check_output_path

__all__ = ["PbsdfFileError", "PbsdfTable", "KAIST_WAVELENGTHS", "MITSUBA_BANDS", "read_pbsdf", "write_pbsdf", "write_table",
           "read_tensor_file", "table_nbytes", "rusinkiewicz_to_directions", "directions_to_rusinkiewicz",
           "table_frame_x"]

#: the band centres of the KAIST database (nm), the export's default for n, k given per band
KAIST_WAVELENGTHS = (450, 500, 550, 600, 650)
#: Mitsuba's loader reads exactly this many wavelengths
MITSUBA_BANDS = 5
_MAGIC = b"tensor_file\0"
#: Mitsuba's struct type codes (sj::Type) <-> NumPy
_DTYPES = {1: np.uint8, 2: np.int8, 3: np.uint16, 4: np.int16, 5: np.uint32, 6: np.int32,
           7: np.uint64, 8: np.int64, 9: np.float16, 10: np.float32, 11: np.float64}
_CODES = {np.dtype(v): k for k, v in _DTYPES.items()}
_FIELDS = ("theta_h", "theta_d", "phi_d", "wvls", "M")
class PbsdfFileError(InputFileError):
    """A file that is not a readable ``measured_polarized`` table (the message names it)."""


# ---------------------------------------------------------------------------------------------
# the TensorFile container

def read_tensor_file(path) -> dict:
    """The fields of a Mitsuba ``TensorFile`` as read-only NumPy arrays (memory-mapped).

    Raises :class:`PbsdfFileError` naming the file for a missing file, a bad header, an unknown
    type, or a field that runs past the end of the file (a truncated download).
    """
    path = Path(path)
    try:       # the input gate: a regular file (no FIFO, no device), never stdin (it is memory-mapped)
        size = check_input(path, "pBSDF file", limit=1 << 50, stdin=False).stat().st_size
    except UsageError as exc:
        raise PbsdfFileError(str(exc)) from None
    try:
        with open(path, "rb") as f:
            head = f.read(min(size, 1 << 20))
    except OSError as exc:
        raise PbsdfFileError(f"pBSDF file {str(path)!r}: cannot read it ({exc.strerror or exc})") from None
    if len(head) < 18 or head[:12] != _MAGIC:
        raise PbsdfFileError(f"pBSDF file {str(path)!r} is not a Mitsuba tensor file (no 'tensor_file' header)")
    if head[12] != 1:
        raise PbsdfFileError(f"pBSDF file {str(path)!r}: unknown tensor file version {head[12]}.{head[13]}")
    (count,) = struct.unpack_from("<I", head, 14)
    pos, fields = 18, {}
    try:
        for _ in range(count):
            (nlen,) = struct.unpack_from("<H", head, pos)
            name = head[pos + 2:pos + 2 + nlen].decode("utf-8")
            pos += 2 + nlen
            ndim, code, offset = struct.unpack_from("<HBQ", head, pos)
            pos += 11
            shape = struct.unpack_from("<" + "Q" * ndim, head, pos)
            pos += 8 * ndim
            if code not in _DTYPES:
                raise PbsdfFileError(f"pBSDF file {str(path)!r}: field {name!r} has an unknown type code {code}")
            dtype = np.dtype(_DTYPES[code])
            try:       # Python integers (no uint64 wrap-around), the file's size, the memory
                check_dimensions(shape, dtype.itemsize, f"pBSDF file {str(path)!r}: field {name!r}",
                                 available_in_file=max(size - offset, 0), option="give a smaller table")
            except UsageError as exc:
                raise PbsdfFileError(str(exc)) from None
            fields[name] = (dtype, tuple(int(s) for s in shape), int(offset))
    except (struct.error, UnicodeDecodeError):
        raise PbsdfFileError(f"pBSDF file {str(path)!r}: the tensor file header is truncated or corrupt") from None
    out = {}
    for name, (dtype, shape, offset) in fields.items():
        if int(np.prod(shape)) == 0:
            out[name] = np.zeros(shape, dtype)
        else:
            out[name] = np.memmap(path, dtype=dtype, mode="r", offset=offset, shape=shape)
    return out


def _header(fields: dict, align: int = 8):
    """(header bytes, {name: offset}) of a tensor file holding ``fields`` (name -> (dtype, shape))."""
    head = bytearray(_MAGIC + struct.pack("<BBI", 1, 0, len(fields)))
    for name, (dtype, shape) in fields.items():
        label = name.encode("utf-8")
        head += struct.pack("<H", len(label)) + label + struct.pack("<HB", len(shape), _CODES[np.dtype(dtype)])
        head += struct.pack("<Q", 0) + struct.pack("<" + "Q" * len(shape), *shape)
    offsets, pos = {}, len(head)
    for name, (dtype, shape) in fields.items():
        pos = (pos + align - 1) // align * align
        offsets[name] = pos
        pos += int(np.prod(shape)) * np.dtype(dtype).itemsize
    # patch the offsets into the header
    cursor = 18
    for name, (dtype, shape) in fields.items():
        cursor += 2 + len(name.encode("utf-8")) + 3
        struct.pack_into("<Q", head, cursor, offsets[name])
        cursor += 8 + 8 * len(shape)
    return bytes(head), offsets, pos


def table_nbytes(n_phi: int, n_theta_d: int, n_theta_h: int, bands: int = MITSUBA_BANDS) -> int:
    """Size in bytes of a table file of this resolution (header and grids included, approximately)."""
    return 4 * 16 * n_phi * n_theta_d * n_theta_h * bands + 4 * (n_phi + n_theta_d + n_theta_h) + 512


def write_pbsdf(path, theta_h, theta_d, phi_d, wavelengths, M, extra: dict | None = None,
                progress=None) -> Path:
    """Write a ``measured_polarized`` table atomically (:func:`write_table` into a temporary file
    beside ``path``, renamed over it when complete)."""
    path = check_output_path(path, "pBSDF file")
    with atomic_path(path) as tmp:
        write_table(tmp, theta_h, theta_d, phi_d, wavelengths, M, extra, progress)
    return path


def write_table(path, theta_h, theta_d, phi_d, wavelengths, M, extra: dict | None = None, progress=None) -> dict:
    """Write a ``measured_polarized`` table into the file ``path`` (the one writer of the format);
    returns each field's byte offset.

    ``M`` is an array of shape (N_pd, N_td, N_th, K, 4, 4) (any float type, written as float32)
    or an iterable yielding N_pd slabs of shape (N_td, N_th, K, 4, 4) in order (streamed: only
    one slab is in memory).  ``extra``: more fields, name -> array or str (a str is stored as
    uint8 UTF-8 text; Mitsuba ignores extra fields), written between the grids and ``M``.
    ``progress(i, n)`` is called per slab.
    """
    grids = {"theta_h": np.asarray(theta_h, np.float32).reshape(1, -1),
             "theta_d": np.asarray(theta_d, np.float32).reshape(1, -1),
             "phi_d": np.asarray(phi_d, np.float32).reshape(1, -1),
             "wvls": np.asarray(np.round(wavelengths), np.uint16).reshape(-1)}
    shape = (grids["phi_d"].shape[1], grids["theta_d"].shape[1], grids["theta_h"].shape[1],
             grids["wvls"].shape[0], 4, 4)
    extras = {}
    for name, value in (extra or {}).items():
        if name in _FIELDS:
            raise UsageError(f"extra field {shorten(name)} clashes with a table field")
        extras[name] = (np.frombuffer(value.encode("utf-8"), np.uint8) if isinstance(value, str)
                        else np.ascontiguousarray(value))
    small = {**grids, **extras}
    layout = {n: (a.dtype, a.shape) for n, a in small.items()}
    layout["M"] = (np.dtype(np.float32), shape)       # last: streamed after the small fields
    head, offsets, total = _header(layout)
    slabs = [M] if isinstance(M, np.ndarray) else M
    if isinstance(M, np.ndarray) and M.shape != shape:
        raise UsageError(f"M has shape {M.shape}; the grids need {shape}")
    with open(path, "wb") as f:
        f.write(head)
        for name, a in small.items():
            f.seek(offsets[name])
            f.write(np.ascontiguousarray(a).tobytes())
        f.seek(offsets["M"])
        written = 0
        for i, slab in enumerate(slabs):
            slab = np.ascontiguousarray(slab, dtype=np.float32)
            f.write(slab.tobytes())
            written += slab.size
            if progress is not None:
                progress(i + 1, shape[0])
        if written != int(np.prod(shape)):
            raise UsageError(f"M: {written} values written, the grids need {int(np.prod(shape))}")
    return offsets


# ---------------------------------------------------------------------------------------------
# the table's coordinates: Rusinkiewicz angles and the Stokes frame

def _normalize(v):
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def rusinkiewicz_to_directions(phi_d, theta_d, theta_h):
    """(omega_i, omega_r, x): unit directions to the light and to the observer (float64 [..., 3])
    of isotropic Rusinkiewicz coordinates, with h in the x-z plane, and the table's Stokes x axis
    normalize(omega_i x omega_r) -- here as normalize(u x h), u = cos phi_d t + sin phi_d b, its
    value for theta_d > 0 and its limit at theta_d = 0 (where omega_i = omega_r)."""
    pd, td, th = np.broadcast_arrays(*(np.asarray(a, float) for a in (phi_d, theta_d, theta_h)))
    zero = np.zeros_like(th)
    h = np.stack([np.sin(th), zero, np.cos(th)], -1)
    t = np.stack([np.cos(th), zero, -np.sin(th)], -1)
    b = np.stack([zero, np.ones_like(th), zero], -1)
    u = np.cos(pd)[..., None] * t + np.sin(pd)[..., None] * b
    om_i = np.cos(td)[..., None] * h + np.sin(td)[..., None] * u
    om_r = np.cos(td)[..., None] * h - np.sin(td)[..., None] * u
    return om_i, om_r, _normalize(np.cross(u, h))


def directions_to_rusinkiewicz(om_i, om_r):
    """(phi_d, theta_d, theta_h) of directions to the light and the observer, as Mitsuba's
    ``directions_to_rusinkiewicz(wo, wi)`` computes them (NaN phi_d at theta_h = 0, as there)."""
    om_i = _normalize(np.asarray(om_i, float))
    om_r = _normalize(np.asarray(om_r, float))
    h = _normalize(om_i + om_r)
    n = np.array([0.0, 0.0, 1.0])
    with np.errstate(invalid="ignore", divide="ignore"):
        b = _normalize(np.cross(n, h))
        t = _normalize(np.cross(b, h))
        td = np.arccos(np.clip(np.sum(h * om_i, -1), -1, 1))
        th = np.arccos(np.clip(h[..., 2], -1, 1))
        ip = _normalize(om_i - np.sum(om_i * h, -1, keepdims=True) * h)
        pd = np.arctan2(np.clip(np.sum(b * ip, -1), -1, 1), np.clip(np.sum(t * ip, -1), -1, 1))
    return pd, td, th


def table_frame_x(om_i, om_r):
    """The table's Stokes x axis normalize(omega_i x omega_r) (NaN where omega_i = omega_r)."""
    with np.errstate(invalid="ignore", divide="ignore"):
        return _normalize(np.cross(om_i, om_r))


# ---------------------------------------------------------------------------------------------
# the table

@dataclass
class PbsdfTable:
    """A ``measured_polarized`` table: grids in radians (float64), wavelengths in nm, and ``M``
    (float32, shape (N_pd, N_td, N_th, K, 4, 4), the table's frames, 1/sr; memory-mapped when
    read from a file).  ``extra``: the file's other fields (``hyde_export`` decoded from JSON)."""

    theta_h: np.ndarray
    theta_d: np.ndarray
    phi_d: np.ndarray
    wavelengths: np.ndarray
    M: np.ndarray
    source: str = "<memory>"
    extra: dict = field(default_factory=dict)

    @property
    def shape(self) -> tuple:
        return tuple(self.M.shape)

    @property
    def resolution(self) -> str:
        return f"{self.phi_d.size}x{self.theta_d.size}x{self.theta_h.size}"

    def grid_directions(self):
        """(omega_i, omega_r, x) of every (phi_d, theta_d, theta_h) node, shapes (N_pd, N_td, N_th, 3)."""
        return rusinkiewicz_to_directions(self.phi_d[:, None, None], self.theta_d[None, :, None],
                                          self.theta_h[None, None, :])

    def interpolate(self, phi_d, theta_d, theta_h, wavelength):
        """The table at arbitrary coordinates, as Mitsuba's lookup does it: multilinear in
        (phi_d, theta_d, theta_h, wavelength), each clamped to its grid; a NaN M00 zeroes the matrix
        and M00 < 0 is clamped to 0.  Returns float64 (..., 4, 4) in the table's frames."""
        coords = np.broadcast_arrays(*(np.asarray(c, float) for c in (phi_d, theta_d, theta_h, wavelength)))
        shape = coords[0].shape
        coords = [c.ravel() for c in coords]
        grids = [self.phi_d, self.theta_d, self.theta_h, np.asarray(self.wavelengths, float)]
        idx, wts = [], []
        for c, g in zip(coords, grids):
            if g.size == 1:
                idx.append(np.zeros(c.size, int))
                wts.append(np.zeros(c.size))
                continue
            i = np.clip(np.searchsorted(g, c, side="left") - 1, 0, g.size - 2)
            with np.errstate(invalid="ignore"):
                w = np.clip((c - g[i]) / (g[i + 1] - g[i]), 0.0, 1.0)
            idx.append(i)
            wts.append(w)
        out = np.zeros((coords[0].size, 4, 4))
        flat = self.M
        for corner in range(16):
            bits = [(corner >> d) & 1 for d in range(4)]
            w = np.ones(coords[0].size)
            sel = []
            for d in range(4):
                if grids[d].size == 1:
                    if bits[d]:
                        w = w * 0.0
                    sel.append(idx[d])
                    continue
                w = w * (wts[d] if bits[d] else 1.0 - wts[d])
                sel.append(idx[d] + bits[d])
            out += w[:, None, None] * np.asarray(flat[sel[0], sel[1], sel[2], sel[3]], float)
        bad = ~np.isfinite(out[:, 0, 0])
        out[bad] = 0.0
        out[:, 0, 0] = np.maximum(out[:, 0, 0], 0.0)
        return out.reshape(shape + (4, 4))

    def interpolate_directions(self, om_i, om_r, wavelength):
        """:meth:`interpolate` at directions to the light and observer (..., 3); 0 below the horizon."""
        pd, td, th = directions_to_rusinkiewicz(om_i, om_r)
        out = self.interpolate(pd, td, th, wavelength)
        up = (np.asarray(om_i)[..., 2] > 0) & (np.asarray(om_r)[..., 2] > 0)
        return np.where(up[..., None, None], out, 0.0)


def _grid(name, a, path):
    a = np.asarray(a, float).reshape(-1)
    if a.size < 1 or not np.all(np.isfinite(a)):
        raise PbsdfFileError(f"pBSDF file {path!r}: grid {name!r} must be finite numbers")
    if a.size > 1 and not np.all(np.diff(a) > 0):
        raise PbsdfFileError(f"pBSDF file {path!r}: grid {name!r} must increase strictly "
                             f"(Mitsuba's interpolation searches it)")
    return a


def read_pbsdf(path) -> PbsdfTable:
    """Read a ``measured_polarized`` file (see the module docstring); ``M`` stays memory-mapped.

    Checks what Mitsuba's loader checks (field names, dtypes, ranks, matching shapes) and more:
    increasing, finite grids in radians (theta in [0, pi/2], phi_d in [-pi, pi], checked with a
    1e-4 margin), 1-5 wavelengths in 300-1100 nm.  Every refusal is a :class:`PbsdfFileError`
    (a :class:`~hyde_bsdf.errors.UsageError`) naming the file and the field.
    """
    name = str(path)
    fields = read_tensor_file(path)
    missing = [f for f in _FIELDS if f not in fields]
    if missing:
        raise PbsdfFileError(f"pBSDF file {name!r} lacks the field(s) {', '.join(missing)} of a "
                             f"measured_polarized table (it has {', '.join(fields) or 'none'})")
    expect = {"theta_h": (np.float32, 2), "theta_d": (np.float32, 2), "phi_d": (np.float32, 2),
              "wvls": (np.uint16, 1), "M": (np.float32, 6)}
    for f, (dt, nd) in expect.items():
        a = fields[f]
        if a.dtype != np.dtype(dt) or a.ndim != nd:
            raise PbsdfFileError(f"pBSDF file {name!r}: field {f!r} must be {np.dtype(dt).name} of rank {nd} "
                                 f"(Mitsuba's loader refuses anything else), got {a.dtype.name} of shape {a.shape}")
    th, td, pd = (_grid(f, fields[f], name) for f in ("theta_h", "theta_d", "phi_d"))
    wv = np.asarray(fields["wvls"], float)
    M = fields["M"]
    want = (pd.size, td.size, th.size, wv.size, 4, 4)
    if M.shape != want:
        raise PbsdfFileError(f"pBSDF file {name!r}: M has shape {M.shape}; the grids need {want} "
                             f"(phi_d, theta_d, theta_h, wavelengths, 4, 4)")
    eps = 1e-4
    for f, a, lo, hi in (("theta_h", th, 0.0, math.pi / 2), ("theta_d", td, 0.0, math.pi / 2),
                         ("phi_d", pd, -math.pi, math.pi)):
        if a.min() < lo - eps or a.max() > hi + eps:
            raise PbsdfFileError(f"pBSDF file {name!r}: grid {f!r} spans {a.min():.4g}..{a.max():.4g}; "
                                 f"it must lie in [{lo:.4g}, {hi:.4g}] radians")
    if not 1 <= wv.size <= MITSUBA_BANDS or np.any((wv < 300) | (wv > 1100)) or \
            (wv.size > 1 and not np.all(np.diff(wv) > 0)):
        raise PbsdfFileError(f"pBSDF file {name!r}: wvls must be 1-{MITSUBA_BANDS} increasing wavelengths in "
                             f"300-1100 nm (Mitsuba reads exactly 5), got {wv.tolist()}")
    extra = {}
    for f, a in fields.items():
        if f in _FIELDS:
            continue
        if f == "hyde_export" and a.dtype == np.uint8:
            try:
                extra[f] = json.loads(bytes(np.asarray(a)).decode("utf-8"))
                continue
            except (ValueError, UnicodeDecodeError, RecursionError):      # not our JSON: kept as bytes
                pass
        extra[f] = a
    return PbsdfTable(theta_h=th, theta_d=td, phi_d=pd, wavelengths=wv, M=M, source=name, extra=extra)
