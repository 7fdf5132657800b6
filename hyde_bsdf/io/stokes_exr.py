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

Camera Stokes data (:func:`write_camera_stokes`, :func:`read_camera_stokes`): any subset of S0..S3
containing S0, mono (``S0, S1, S2``) or any colour/spectral suffixes (``S0.R``, ``S0.550nm``), with
optional standard-deviation layers ``S0_sigma[.R]`` ... and a ``mask`` channel -- what a
polarization camera's Stokes step gives and ``invert --maps`` reads.

The derived quantities (intensity, DoLP, AoLP, DoCP) are in
:mod:`hyde_bsdf.render.polarization`; the PNG charts in :mod:`hyde_bsdf.app.pictures`.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from hyde_bsdf.io.atomic import atomic_path
from hyde_bsdf.errors import InputFileError, UsageError
from hyde_bsdf.io.input_gate import check_dimensions, check_input


__all__ = [
    "open_exr",
    "STOKES_NAMES",
    "COLOURS",
    "exr_channel_names",
    "exr_bytes",
    "write_stokes_exr",
    "read_stokes_exr",
    "camera_channel_names",
    "write_camera_stokes",
    "read_camera_stokes",
]


def open_exr(path, what: str = "EXR file"):
    """``OpenEXR.File`` of ``path`` with its channels read separately, once its header's size (width x
    height x channels, 4 bytes each) has passed the memory check; UsageError for an unreadable file."""
    import OpenEXR

    from hyde_bsdf.io.arrays import exr_shape

    check_dimensions(exr_shape(path, what), 4, f"{what} {str(path)!r}", option="give a smaller image")
    try:
        return OpenEXR.File(str(path), separate_channels=True)
    except Exception as exc:  # noqa: BLE001 -- any unreadable file is a user's input problem
        raise InputFileError(f"{what} {str(path)!r}: not a readable OpenEXR file ({type(exc).__name__})") from None


STOKES_NAMES = ("S0", "S1", "S2", "S3")
COLOURS = ("R", "G", "B")
def exr_channel_names() -> list[str]:
    """The channel names written by :func:`write_stokes_exr`, in order."""
    return list(COLOURS) + [f"{s}.{c}" for s in STOKES_NAMES for c in COLOURS]


#: bytes an EXR file may hold besides its pixels: the header (channel list, attributes, metadata)
EXR_HEADER_BYTES = 1 << 16


def exr_bytes(width: int, height: int, channels: int) -> int:
    """Upper bound of the size of a ``width`` x ``height`` EXR of ``channels`` float32 channels as
    the writers here make it (ZIP compression, 16 scanlines a chunk): the pixels uncompressed
    (zlib never grows data by more than 0.1 %, counted), 16 bytes of offset and chunk header per
    chunk, and :data:`EXR_HEADER_BYTES`.  What the output gate's free-space check is given."""
    pixels = int(width) * int(height) * int(channels) * 4
    return pixels + pixels // 1000 + 16 * (-(-int(height) // 16)) + EXR_HEADER_BYTES


def _check_stokes(stokes: dict) -> tuple[int, int]:
    """Validate a Stokes image dict; returns its (H, W)."""
    if not isinstance(stokes, dict):
        raise UsageError(f"stokes must be a dict with keys {STOKES_NAMES}, got {type(stokes).__name__}")
    missing = [s for s in STOKES_NAMES if s not in stokes]
    if missing:
        raise UsageError(f"stokes is missing the component(s) {missing}; it needs {list(STOKES_NAMES)}")
    shape = np.shape(stokes["S0"])
    if len(shape) != 3 or shape[2] != 3 or shape[0] < 1 or shape[1] < 1:
        raise UsageError(f"stokes['S0'] must have shape (H, W, 3), got {shape}")
    for name in STOKES_NAMES[1:] + (("RGB",) if "RGB" in stokes else ()):
        if np.shape(stokes[name]) != shape:
            raise UsageError(f"stokes[{name!r}] has shape {np.shape(stokes[name])}, expected {shape}")
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
            raise UsageError(f"stokes['RGB'] must have shape (H, W, 3), got {shape}")
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
        raise UsageError(f"stokes has non-finite values in channel(s) {bad}; refusing to write {path}")
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
    """Read a full Stokes EXR (ours or one Mitsuba's ``stokes`` integrator wrote): S0..S3 in R, G, B.

    Returns a dict ``{"RGB", "S0", "S1", "S2", "S3"}`` of float32 arrays (H, W, 3)
    and ``"metadata"``: the ``hyde_bsdf.*`` header attributes as strings.  The file is read by
    :func:`read_camera_stokes` (the one reader); InputFileError naming the missing channels if it is
    not a full RGB Stokes image.
    """
    data = read_camera_stokes(path, "Stokes EXR")
    missing = [f"{s}.{c}" for s in STOKES_NAMES for c in COLOURS if s not in data["stokes"] or c not in data["colours"]]
    if missing:
        raise InputFileError(f"{path} is not a Stokes EXR: channels {missing} are missing")
    out = {s: data["stokes"][s][..., [data["colours"].index(c) for c in COLOURS]].astype(np.float32)
           for s in STOKES_NAMES}
    out["RGB"] = out["S0"].copy() if data["rgb"] is None else data["rgb"]
    out["metadata"] = data["metadata"]
    return out


# camera Stokes images: any subset of S0..S3, mono or any colour/spectral channels, sigma and mask

#: suffix of the standard-deviation layer of a component: ``S0_sigma.R`` (or ``S0_sigma`` when mono)
SIGMA_SUFFIX = "_sigma"
MASK_CHANNEL = "mask"


def camera_channel_names(components, colours=()) -> list[str]:
    """EXR channel names of camera Stokes data: ``S0.R ...`` for colours (R, G, B; or spectral
    names such as ``550nm``), ``S0, S1, S2`` for mono (``colours`` empty)."""
    return [f"{c}.{x}" if x else c for c in components for x in (tuple(colours) or ("",))]


def write_camera_stokes(path, stokes: dict, sigma: dict | None = None, mask=None, colours=(),
                        metadata: dict | None = None) -> Path:
    """Write camera Stokes data to an EXR, atomically: ``stokes``/``sigma`` map component names
    (S0 and any of S1..S3) to arrays (H, W) (mono, ``colours`` empty) or (H, W, C) with C =
    len(``colours``); ``mask`` bool (H, W) (1 = usable) as channel ``mask``.  Channels:
    :func:`camera_channel_names` plus ``S0_sigma[.R]`` ... and ``mask``; ``invert --maps`` and
    :func:`read_camera_stokes` read it.  Non-finite values are refused."""
    import OpenEXR

    path = Path(path)
    if path.suffix.lower() != ".exr":
        raise UsageError(f"path must end in .exr, got {str(path)!r}")
    comps = [c for c in STOKES_NAMES if c in stokes]
    if "S0" not in comps:
        raise UsageError(f"stokes must hold S0 (and any of S1..S3), got {sorted(stokes)}")
    colours = tuple(colours)
    shape = np.shape(stokes["S0"])
    want = shape[:2] + ((len(colours),) if colours else ())
    channels: dict[str, np.ndarray] = {}
    for layer, data in (("", stokes), (SIGMA_SUFFIX, sigma or {})):
        for c in comps if layer == "" else [c for c in comps if c in data]:
            arr = np.asarray(data[c], np.float32)
            if arr.shape != want:
                raise UsageError(f"{c}{layer} has shape {arr.shape}, expected {want} (colours {list(colours)})")
            for j, name in enumerate(camera_channel_names([c + layer], colours)):
                channels[name] = np.ascontiguousarray(arr[..., j] if colours else arr)
    if mask is not None:
        channels[MASK_CHANNEL] = np.ascontiguousarray(np.asarray(mask, np.float32).reshape(shape[:2]))
    bad = [name for name, a in channels.items() if not np.all(np.isfinite(a))]
    if bad:
        raise UsageError(f"non-finite values in channel(s) {bad}; refusing to write {path}")
    header = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage,
              "hyde_bsdf.stokes_basis": "Mitsuba sensor basis: x = image right, y = image up, k = towards the viewer"}
    for key, value in (metadata or {}).items():
        header[f"hyde_bsdf.{key}"] = str(value)
    path.parent.mkdir(parents=True, exist_ok=True)
    with atomic_path(path) as tmp:
        OpenEXR.File(header, dict(channels)).write(str(tmp))
        _verify_exr(tmp, channels)
    return path


def _layers(names) -> dict:
    """{layer: [channel suffixes]} of EXR channel names ``LAYER.SUFFIX`` or plain ``LAYER`` ('')."""
    out: dict = {}
    for n in names:
        layer, _, suffix = n.partition(".")
        out.setdefault(layer, []).append(suffix)
    return out


def read_camera_stokes(path, what: str = "camera Stokes EXR") -> dict:
    """Read camera Stokes data from an EXR: Mitsuba's (``S0.R ... S3.B``), plain mono ``S0, S1, S2[, S3]``,
    any colour or spectral channel suffixes, with optional ``S0_sigma...`` layers and a ``mask``.

    Returns ``{"stokes": {name: (H, W, C)}, "sigma": {name: (H, W, C)}, "mask": (H, W) bool or None,
    "colours": tuple of suffixes (("",) for mono), "rgb": the plain R, G, B channels (H, W, 3) float32
    or None, "metadata": {...}}`` -- only the components present (the camera's measured ones).  The
    file passes the input gate first; UsageError naming it when S0 is missing or the components'
    channel suffixes differ."""
    path = check_input(path, what, stdin=False)        # the input gate: a regular file, no FIFO
    f = open_exr(path, what)                           # its size from its header first
    try:
        chans = {name: ch.pixels for name, ch in f.channels().items()}
    except Exception as exc:  # noqa: BLE001 -- any unreadable file is a user's input problem
        raise InputFileError(f"{path}: not a readable OpenEXR file ({type(exc).__name__})") from None
    layers = _layers(chans)
    if "S0" not in layers:
        raise InputFileError(f"{path} is not a Stokes EXR: no S0 channel (found {sorted(chans)}); a Stokes EXR has "
                             "S0[.R ...], S1, S2[, S3]")
    colours = tuple(sorted(layers["S0"], key=lambda x: ("RGB".find(x) if x in "RGB" and x else 9, x)))
    out: dict = {"stokes": {}, "sigma": {}, "colours": colours}
    for c in STOKES_NAMES:
        for key, layer in (("stokes", c), ("sigma", c + SIGMA_SUFFIX)):
            if layer not in layers:
                continue
            if sorted(layers[layer]) != sorted(colours):
                raise InputFileError(f"{path}: {layer} has channels {sorted(layers[layer])} but S0 has {sorted(colours)}")
            out[key][c] = np.stack([chans[f"{layer}.{x}" if x else layer] for x in colours], axis=-1).astype(np.float64)
    mask = chans.get(MASK_CHANNEL)
    out["mask"] = None if mask is None else np.asarray(mask) > 0.5
    out["rgb"] = (np.stack([chans[c] for c in COLOURS], axis=-1).astype(np.float32)
                  if all(c in chans for c in COLOURS) else None)
    out["metadata"] = {k[len("hyde_bsdf."):]: str(v) for k, v in f.header().items()
                       if isinstance(k, str) and k.startswith("hyde_bsdf.")}
    return out
