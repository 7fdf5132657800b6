"""Polarization quantities of a Stokes image: luminance, intensity, DoLP, AoLP, DoCP.

A Stokes image is the dict :mod:`hyde_bsdf.io.stokes_exr` describes (``"S0".."S3"``, arrays
(H, W, 3), linear sRGB, Mitsuba's sensor basis).  Derived quantities (computed from the luminance
``Y = 0.2126 R + 0.7152 G + 0.0722 B`` of each component, or from one colour channel):

* intensity ``I = S0``,
* degree of linear polarization ``DoLP = sqrt(S1^2 + S2^2) / S0`` in [0, 1],
* angle of linear polarization ``AoLP = atan2(S2, S1) / 2`` in (-pi/2, pi/2],
  radians, counter-clockwise from the image's horizontal as seen by the viewer,
* degree of circular polarization ``DoCP = S3 / S0`` in [-1, 1] (signed).

Where ``S0`` is zero (or not positive) the ratios are undefined: they are set
to 0 and reported in the ``valid`` mask of :func:`polarization_quantities`.
"""
from __future__ import annotations

import numpy as np

from hyde_bsdf.errors import UsageError

from hyde_bsdf.io.stokes_exr import COLOURS, STOKES_NAMES, _check_stokes

__all__ = ["LUMINANCE_WEIGHTS", "luminance", "polarization_quantities", "tonemap"]

#: Rec. 709 / sRGB luminance weights for linear RGB.
LUMINANCE_WEIGHTS = np.array([0.2126, 0.7152, 0.0722])


#: S0 at or below this is treated as "no light" when forming ratios (float32 noise floor).
S0_FLOOR = 1e-12


def luminance(image, channel: str = "Y") -> np.ndarray:
    """One scalar per pixel from an (H, W, 3) linear-RGB array.

    channel: ``"Y"`` (Rec. 709 luminance, the default) or one of ``"R", "G", "B"``.
    """
    image = np.asarray(image, dtype=np.float64)
    if image.ndim != 3 or image.shape[2] != 3:
        raise UsageError(f"image must have shape (H, W, 3), got {image.shape}")
    if channel == "Y":
        return image @ LUMINANCE_WEIGHTS
    if channel in COLOURS:
        return image[..., COLOURS.index(channel)]
    raise UsageError(f"channel must be one of 'Y', 'R', 'G', 'B', got {channel!r}")


def polarization_quantities(stokes: dict, channel: str = "Y") -> dict:
    """Intensity, DoLP, AoLP (radians) and DoCP of a Stokes image.

    Returns a dict of float64 arrays (H, W): ``intensity`` (S0), ``dolp`` in [0, 1],
    ``aolp`` in (-pi/2, pi/2] (radians, counter-clockwise from the image horizontal
    as seen by the viewer), ``docp`` in [-1, 1], and ``valid`` (bool): S0 > 0, where
    the ratios are defined.  Where ``valid`` is False, dolp/aolp/docp are 0.
    DoLP and |DoCP| are clipped to 1 (Monte-Carlo noise can push a ratio of two
    estimates past 1; a physical Stokes vector never exceeds it).
    """
    _check_stokes(stokes)
    s0, s1, s2, s3 = (luminance(stokes[s], channel) for s in STOKES_NAMES)
    for name, arr in zip(STOKES_NAMES, (s0, s1, s2, s3)):
        if not np.all(np.isfinite(arr)):
            raise UsageError(f"stokes[{name!r}] has non-finite values")
    valid = s0 > S0_FLOOR
    safe_s0 = np.where(valid, s0, 1.0)  # placeholder divisor where undefined; masked below
    dolp = np.where(valid, np.minimum(np.hypot(s1, s2) / safe_s0, 1.0), 0.0)
    aolp = np.where(valid, 0.5 * np.arctan2(s2, s1), 0.0)
    docp = np.where(valid, np.clip(s3 / safe_s0, -1.0, 1.0), 0.0)
    return {"intensity": s0, "dolp": dolp, "aolp": aolp, "docp": docp, "valid": valid}


def tonemap(rgb: np.ndarray, exposure: float = 1.0) -> np.ndarray:
    """Linear RGB -> 8-bit-ready sRGB in [0, 1] (clip, then the sRGB transfer curve)."""
    x = np.clip(np.asarray(rgb, dtype=np.float64) * exposure, 0.0, 1.0)
    return np.where(x <= 0.0031308, 12.92 * x, 1.055 * np.power(x, 1 / 2.4) - 0.055)

