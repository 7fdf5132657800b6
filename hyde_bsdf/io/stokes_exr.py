"""Stokes images as OpenEXR files: the layout, the writer and the reader.

A *Stokes image* here is a dict of float32 arrays of shape ``(H, W, 3)``
(one value per RGB channel, linear sRGB primaries, the scene's radiance units):

``"S0"``, ``"S1"``, ``"S2"``, ``"S3"``
    the Stokes components as Mitsuba's ``stokes`` integrator reports them,
    i.e. in the **sensor's basis**: for light travelling towards the camera
    (propagation ``k = -ray.d``) the first basis vector is
    ``x = normalize(ray.d x up)`` with ``up`` the sensor's up axis -- which is
    the image's rightward direction -- and ``y = k x x`` is the image's upward
    direction.  ``S1 > 0``: horizontal polarization (along the image rows);
    ``S2 > 0``: linear polarization at +45 deg (from image-right towards
    image-up, as seen by the viewer); ``S3``: Mitsuba's circular component.
``"RGB"`` (optional)
    the ordinary colour image (equal to ``S0`` for a Stokes render).

The EXR layout is one float32 channel per component and colour:
``R, G, B, S0.R, S0.G, S0.B, S1.R, ..., S3.B`` -- the names Mitsuba's
``stokes`` integrator gives its channels, so ``mi.Bitmap(path).split()`` reads
our files and we read Mitsuba's.

The derived quantities (intensity, DoLP, AoLP, DoCP) are in
:mod:`hyde_bsdf.render.polarization`; the PNG charts in :mod:`hyde_bsdf.app.pictures`.

May import: the standard library, NumPy, :mod:`hyde_bsdf.errors`, :mod:`hyde_bsdf.io.atomic`
(OpenEXR lazily, inside the reader and writer).
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from hyde_bsdf.io.atomic import atomic_path
from hyde_bsdf.errors import UsageError

__all__ = [
    "STOKES_NAMES",
    "COLOURS",
    "exr_channel_names",
    "write_stokes_exr",
    "read_stokes_exr",
]

STOKES_NAMES = ("S0", "S1", "S2", "S3")
COLOURS = ("R", "G", "B")
def exr_channel_names() -> list[str]:
    """The channel names written by :func:`write_stokes_exr`, in order."""
    return list(COLOURS) + [f"{s}.{c}" for s in STOKES_NAMES for c in COLOURS]


def _check_stokes(stokes: dict) -> tuple[int, int]:
    """Validate a Stokes image dict; returns its (H, W)."""
    if not isinstance(stokes, dict):
        raise ValueError(f"stokes must be a dict with keys {STOKES_NAMES}, got {type(stokes).__name__}")
    missing = [s for s in STOKES_NAMES if s not in stokes]
    if missing:
        raise ValueError(f"stokes is missing the component(s) {missing}; it needs {list(STOKES_NAMES)}")
    shape = np.shape(stokes["S0"])
    if len(shape) != 3 or shape[2] != 3 or shape[0] < 1 or shape[1] < 1:
        raise ValueError(f"stokes['S0'] must have shape (H, W, 3), got {shape}")
    for name in STOKES_NAMES[1:] + (("RGB",) if "RGB" in stokes else ()):
        if np.shape(stokes[name]) != shape:
            raise ValueError(f"stokes[{name!r}] has shape {np.shape(stokes[name])}, expected {shape}")
    return shape[0], shape[1]


def write_stokes_exr(path, stokes: dict, metadata: dict | None = None) -> Path:
    """Write a Stokes image to an OpenEXR file (float32 channels, ZIP compressed), atomically.

    Parameters
    ----------
    path : str or Path, must end in ``.exr``
    stokes : dict with ``"S0".."S3"`` (and optionally ``"RGB"``), arrays (H, W, 3); or, for a
        render in an unpolarized variant, a dict with ``"RGB"`` only (then only R, G, B are written)
    metadata : optional dict of short strings stored as EXR header attributes
        (e.g. variant, spp); keys are prefixed ``hyde_bsdf.``.

    Channels: ``R, G, B`` (``RGB`` if given, else ``S0``) then ``S0.R ... S3.B``.
    Non-finite values are refused (ValueError), so no NaN reaches a file silently.  The file is
    written to a temporary file beside ``path`` and renamed over it (:mod:`hyde_bsdf.io.atomic`):
    an interrupted write leaves the previous file intact.
    """
    import OpenEXR

    path = Path(path)
    if path.suffix.lower() != ".exr":
        raise UsageError(f"path must end in .exr, got {str(path)!r}")
    colour_only = isinstance(stokes, dict) and "RGB" in stokes and "S0" not in stokes
    if colour_only:
        shape = np.shape(stokes["RGB"])
        if len(shape) != 3 or shape[2] != 3 or shape[0] < 1 or shape[1] < 1:
            raise ValueError(f"stokes['RGB'] must have shape (H, W, 3), got {shape}")
    else:
        _check_stokes(stokes)
    rgb = np.asarray(stokes.get("RGB", stokes.get("S0")), dtype=np.float32)
    channels: dict[str, np.ndarray] = {}
    for j, c in enumerate(COLOURS):
        channels[c] = np.ascontiguousarray(rgb[..., j])
    for s in () if colour_only else STOKES_NAMES:
        arr = np.asarray(stokes[s], dtype=np.float32)
        for j, c in enumerate(COLOURS):
            channels[f"{s}.{c}"] = np.ascontiguousarray(arr[..., j])
    bad = [name for name, a in channels.items() if not np.all(np.isfinite(a))]
    if bad:
        raise ValueError(f"stokes has non-finite values in channel(s) {bad}; refusing to write {path}")
    header = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}
    if not colour_only:
        header["hyde_bsdf.stokes_basis"] = (
            "Mitsuba sensor basis: x = image right, y = image up, k = towards the viewer")
    for key, value in (metadata or {}).items():
        header[f"hyde_bsdf.{key}"] = str(value)
    path.parent.mkdir(parents=True, exist_ok=True)
    with atomic_path(path) as tmp:
        OpenEXR.File(header, dict(channels)).write(str(tmp))   # a copy: the binding rewrites its dict
        _verify_exr(tmp, channels)
    return path


def _verify_exr(tmp, channels) -> None:
    """Read back what OpenEXR wrote: its C++ stream can swallow the error of the final flush (a
    full disk, a file-size limit) and leave a truncated file without raising.  OSError if so."""
    import errno
    import os

    import OpenEXR

    import sys

    try:
        sys.stdout.flush()
        saved = os.dup(1)            # the binding prints its read warnings on stdout: keep them off it
    except (OSError, ValueError, AttributeError):
        saved = None
    try:
        if saved is not None:
            devnull = os.open(os.devnull, os.O_WRONLY)
            os.dup2(devnull, 1)
            os.close(devnull)
        back = OpenEXR.File(str(tmp), separate_channels=True).channels()
        ok = set(back) == set(channels) and all(
            np.array_equal(back[name].pixels, a) for name, a in channels.items())
    except Exception:  # noqa: BLE001 -- any failure to read back is a failed write
        ok = False
    finally:
        if saved is not None:
            os.dup2(saved, 1)
            os.close(saved)
    if not ok:
        try:
            st = os.statvfs(os.path.dirname(os.path.abspath(tmp)) or ".")
            full = st.f_bavail * st.f_frsize < 1 << 20
        except OSError:
            full = False
        code = errno.ENOSPC if full else errno.EIO
        raise OSError(code, os.strerror(code) if full else
                      "the file written does not read back complete (disk full or a file-size limit?)")


def read_stokes_exr(path) -> dict:
    """Read a Stokes EXR (ours or one Mitsuba's ``stokes`` integrator wrote).

    Returns a dict ``{"RGB", "S0", "S1", "S2", "S3"}`` of float32 arrays (H, W, 3)
    and ``"metadata"``: the ``hyde_bsdf.*`` header attributes as strings.
    Raises ValueError naming the missing channels if it is not a Stokes EXR.
    """
    import OpenEXR

    path = Path(path)
    if not path.is_file():
        raise ValueError(f"path {str(path)!r} is not an existing file")
    f = OpenEXR.File(str(path), separate_channels=True)
    chans = {name: ch.pixels for name, ch in f.channels().items()}
    need = [f"{s}.{c}" for s in STOKES_NAMES for c in COLOURS]
    missing = [n for n in need if n not in chans]
    if missing:
        raise ValueError(f"{path} is not a Stokes EXR: channels {missing} are missing "
                         f"(found {sorted(chans)})")
    out: dict = {}
    for s in STOKES_NAMES:
        out[s] = np.stack([chans[f"{s}.{c}"] for c in COLOURS], axis=-1).astype(np.float32)
    if all(c in chans for c in COLOURS):
        out["RGB"] = np.stack([chans[c] for c in COLOURS], axis=-1).astype(np.float32)
    else:
        out["RGB"] = out["S0"].copy()
    out["metadata"] = {k[len("hyde_bsdf."):]: str(v) for k, v in f.header().items()
                       if isinstance(k, str) and k.startswith("hyde_bsdf.")}
    return out


