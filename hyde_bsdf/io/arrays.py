"""Arrays from ``.npy`` and ``.npz`` files and images, sized from their headers before anything is decoded.

:func:`array_header` reads what a file says its array is, (shape, dtype): the ``.npy`` header (NumPy's
format: a magic string, then a Python-literal dict) or an image's (PIL opens lazily: size and mode,
no pixel).  :func:`read_array` checks that size against the file (a ``.npy`` holds its data: a
229-byte file cannot hold 200000 x 200000 values) and against the available memory, then decodes;
:func:`read_npz` does the same for each member of a ``.npz`` (its header through :mod:`zipfile`).
PIL's own "decompression bomb" limit is replaced by that memory check.  A refusal is one
:class:`~hyde_bsdf.errors.UsageError` naming the file.
"""
from __future__ import annotations

import contextlib
import math
import os

import numpy as np

from hyde_bsdf.errors import InputFileError, UsageError, one_line, shorten
from hyde_bsdf.io.input_gate import check_dimensions, check_input
from hyde_bsdf.resources import format_bytes

__all__ = ["array_header", "read_array", "read_npz", "exr_shape", "image_shape", "check_image_memory", "IMAGE_DTYPES"]

#: PIL image mode -> (dtype, values per pixel)
IMAGE_DTYPES = {"1": (np.bool_, 1), "L": (np.uint8, 1), "P": (np.uint8, 1), "I;16": (np.uint16, 1),
                "I;16B": (np.uint16, 1), "I": (np.int32, 1), "F": (np.float32, 1), "LA": (np.uint8, 2),
                "RGB": (np.uint8, 3), "RGBA": (np.uint8, 4), "CMYK": (np.uint8, 4)}


@contextlib.contextmanager
def _image(path, what):
    """PIL's lazy open of ``path`` without its pixel-count limit (the memory check replaces it)."""
    from PIL import Image

    limit, Image.MAX_IMAGE_PIXELS = Image.MAX_IMAGE_PIXELS, None
    try:
        with Image.open(path) as im:
            yield im
    except (OSError, ValueError, SyntaxError) as exc:       # PIL: UnidentifiedImageError, truncated files
        raise UsageError(f"{what} {shorten(str(path))}: cannot read it as an image "
                         f"({one_line(exc)[:120]})") from None
    finally:
        Image.MAX_IMAGE_PIXELS = limit


def _npy_header(path, what):
    """(shape, dtype, offset of the data) of a ``.npy`` file."""
    try:
        with open(path, "rb") as fh:
            shape, dtype = _read_npy_header(fh, what, shorten(str(path)))
            offset = fh.tell()
    except OSError as exc:
        raise UsageError(f"{what} {shorten(str(path))}: not a readable .npy file ({one_line(exc)[:120]})") from None
    _check_held(shape, dtype, os.path.getsize(path) - offset, f"{what} {shorten(str(path))}")
    return shape, dtype, offset


def _read_npy_header(fh, what, name):
    """(shape, dtype) from the ``.npy`` header at ``fh``'s position (NumPy's format: a magic string,
    then a Python-literal dict), nothing more read."""
    fmt = np.lib.format
    try:
        version = fmt.read_magic(fh)
        read = fmt.read_array_header_1_0 if version == (1, 0) else fmt.read_array_header_2_0
        shape, _, dtype = read(fh)
    except (ValueError, SyntaxError, TypeError) as exc:
        raise UsageError(f"{what} {name}: not a readable .npy array ({one_line(exc)[:120]})") from None
    if dtype.hasobject:
        raise UsageError(f"{what} {name} holds Python objects, not numbers; save a numeric array")
    return tuple(int(d) for d in shape), dtype


def _check_held(shape, dtype, held, name):
    """UsageError when a header's ``shape`` x ``dtype`` needs more than the ``held`` bytes of data."""
    need = math.prod(shape) * dtype.itemsize
    if need > held:
        raise UsageError(f"{name}: its header says {'x'.join(map(str, shape))} {dtype} values "
                         f"({format_bytes(need)}), but the file holds {format_bytes(held)} (truncated or damaged)")


def read_npz(path, what: str = "array file") -> dict:
    """{name: array} of a ``.npz`` file (NumPy's zip of ``.npy`` members, compressed or not): each
    member's header read through :mod:`zipfile` (only its first bytes are inflated) and checked against
    the member's size in the zip's directory, their total against the available memory, before any
    data is decoded."""
    import zipfile

    path = check_input(path, what, stdin=False)
    name = f"{what} {shorten(str(path))}"
    try:
        with zipfile.ZipFile(path) as zf:
            members = [m for m in zf.infolist() if m.filename.endswith(".npy")]
            total = 0
            for m in members:
                with zf.open(m) as fh:
                    shape, dtype = _read_npy_header(fh, what, f"{shorten(str(path))}, array {shorten(m.filename)}")
                    _check_held(shape, dtype, m.file_size - fh.tell(), f"{name}, array {shorten(m.filename)}")
                total += math.prod(shape) * dtype.itemsize
    except (OSError, zipfile.BadZipFile, EOFError) as exc:
        raise UsageError(f"{name}: not a readable .npz file ({one_line(exc)[:120]})") from None
    if not members:
        raise UsageError(f"{name} holds no .npy array: not a .npz file")
    check_dimensions((total,), 1, f"{name}, {len(members)} arrays", option="give a smaller file")
    try:
        with np.load(path, allow_pickle=False) as data:      # its .npy members only (others are not sized)
            return {m.filename[:-4]: data[m.filename[:-4]] for m in members}
    except (OSError, ValueError, zipfile.BadZipFile, EOFError) as exc:
        raise UsageError(f"{name}: not a readable .npz file ({one_line(exc)[:120]})") from None


def array_header(path, what: str = "array file") -> tuple[tuple, np.dtype]:
    """(shape, dtype) of the array in ``path`` (``.npy`` or an image), read from its header only."""
    path = check_input(path, what, stdin=False)
    if str(path).lower().endswith(".npy"):
        return _npy_header(path, what)[:2]
    with _image(path, what) as im:
        dtype, bands = IMAGE_DTYPES.get(im.mode, (np.float64, len(im.getbands())))
        return (im.height, im.width) + ((bands,) if bands > 1 else ()), np.dtype(dtype)


def read_array(path, what: str = "array file") -> np.ndarray:
    """The array in ``path`` (``.npy`` or a PNG/TIFF image), its size checked against the file and the
    available memory before it is decoded (module docstring)."""
    path = check_input(path, what, stdin=False)
    name = f"{what} {shorten(str(path))}"
    if str(path).lower().endswith(".npy"):
        shape, dtype, _ = _npy_header(path, what)
        check_dimensions(shape, dtype.itemsize, name, option="give a smaller array")
        return np.load(path, allow_pickle=False)
    shape, dtype = array_header(path, what)
    check_dimensions(shape, dtype.itemsize, name, option="give a smaller image")
    with _image(path, what) as im:
        return np.asarray(im)


def exr_shape(path, what: str = "EXR file") -> tuple[int, int, int]:
    """(height, width, channels) of an OpenEXR file, from its header (no pixel read)."""
    import OpenEXR

    try:
        header = OpenEXR.File(str(path), header_only=True).header()
        lo, hi = header["dataWindow"]
        return int(hi[1]) - int(lo[1]) + 1, int(hi[0]) - int(lo[0]) + 1, len(header["channels"])
    except Exception as exc:  # noqa: BLE001 -- any unreadable file is a user's input problem
        raise InputFileError(f"{what} {shorten(str(path))}: not a readable OpenEXR file ({type(exc).__name__})") from None


#: image files whose header PIL reads without decoding
PIL_SUFFIXES = (".png", ".jpg", ".jpeg", ".tif", ".tiff", ".bmp", ".tga", ".ppm", ".pgm")


def image_shape(path, what: str = "image") -> tuple | None:
    """(height, width, channels) of an EXR, a Radiance RGBE (``.hdr``, ``.rgbe``), a PFM or a PIL-readable
    image from its header -- every format Mitsuba's ``bitmap`` reads; None for other files."""
    name = str(path).lower()
    if name.endswith(".exr"):
        return exr_shape(path, what)
    if name.endswith((".hdr", ".rgbe", ".pfm")):
        return _text_header_shape(path, what, name.endswith(".pfm"))
    if name.endswith(PIL_SUFFIXES):
        with _image(path, what) as im:
            return im.height, im.width, len(im.getbands())
    return None


def _text_header_shape(path, what, pfm: bool) -> tuple:
    """(height, width, channels) from the text header of a PFM (``PF``/``Pf``, then ``W H``) or a Radiance
    RGBE file (lines up to a blank one, then ``-Y H +X W``); the first 4 KiB are read."""
    try:
        with open(path, "rb") as fh:
            head = fh.read(4096).decode("latin-1")
        if pfm:
            kind, width, height = (head.split(None, 3) + ["", "", ""])[:3]
            if kind in ("PF", "Pf"):
                return int(height), int(width), 3 if kind == "PF" else 1
        else:
            axes = (head.split("\n\n", 1) + [""])[1].split("\n", 1)[0].split()
            if head.startswith("#?") and len(axes) == 4 and {axes[0][1:], axes[2][1:]} == {"Y", "X"}:
                rows, cols = int(axes[1]), int(axes[3])
                return (rows, cols, 3) if axes[0][1:] == "Y" else (cols, rows, 3)
    except (OSError, ValueError):
        pass
    raise InputFileError(f"{what} {shorten(str(path))}: not a readable {'PFM' if pfm else 'Radiance RGBE'} file "
                         "(its header)")


def check_image_memory(path, what: str = "image") -> None:
    """A texture or image file's decoded size (float32 per channel, as a renderer holds it), from its
    header, against the available memory; other files pass.  A header that claims 100000 x 100000 is
    one line before the renderer allocates it."""
    shape = image_shape(path, what)
    if shape is not None:
        check_dimensions(shape, 4, f"{what} {shorten(str(path))}", option="give a smaller image")
