"""Stokes inputs as cameras produce them, turned into the inverse's references.

A camera gives any subset of S0..S3 (a linear polarization camera: S0, S1, S2), in mono, RGB or
spectral channels, possibly with a standard deviation per component and pixel and a mask of usable
pixels.  :func:`camera_reference` accepts

* a Stokes EXR path: Mitsuba's channel names (``S0.R ... S3.B``), plain mono ``S0, S1, S2[, S3]``, any
  colour or spectral suffixes (``S0.550nm``), with optional ``S0_sigma...`` layers and a ``mask``
  channel (:func:`hyde_bsdf.io.stokes_exr.read_camera_stokes`; what ``hyde-bsdf stokes`` writes);
* a :class:`~hyde_bsdf.model.polarimetry.StokesEstimate` (from raw analyzer frames);
* a dict ``{"S0": array, "S1": ..., ["sigma": {"S0": ...}], ["mask": (H, W)]}`` of arrays (H, W) or
  (H, W, C);
* a NumPy array (M, H, W[, C]) of the first M components, or of those named by ``measured``;

and returns the luminance reference (4, H, W) with the measured components (zeros elsewhere), their
names, sigma (4, H, W) (or None) and the mask.  Colour channels reduce to one: ``channel="Y"`` (the
default) is the Rec. 709 luminance of R, G, B -- what the inverse's renders compare against -- and
sigma follows as sqrt(sum w_i^2 sigma_i^2) (independent channels); ``channel="R"`` (or any suffix)
picks one channel, which matches the renders only when the scene's lights and sample are grey, or
the camera is mono.  ``noise`` (a :class:`~hyde_bsdf.model.polarimetry.CameraNoise`) gives sigma when
the data carry none: the data are then in DN above black, and sigma is what ideal DoFP analyzers
(0/45/90/135 deg) with that noise give (:func:`~hyde_bsdf.model.polarimetry.stokes_sigma`).
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from hyde_bsdf.errors import UsageError, shorten
from hyde_bsdf.inverse._common import Y_WEIGHTS
from hyde_bsdf.model.polarimetry import StokesEstimate, stokes_sigma
from hyde_bsdf.inverse.loss import as_mask, check_reference_scale, interior_mask
from hyde_bsdf.inverse.observations import Observation

__all__ = ["camera_reference", "camera_observation", "calibrated_observations", "observations_from_files", "camera_files",
           "impossible_pixels", "ReferenceDataWarning"]

STOKES = ("S0", "S1", "S2", "S3")


class ReferenceDataWarning(UserWarning):
    """Pixels of a reference that no light can give (negative S0, a degree of polarization > 1) or whose
    sigma is unusable; they are left out of the fit."""


def impossible_pixels(ref, sigma=None, what: str = "the reference", sigma_bad=None) -> np.ndarray:
    """(H, W) bool: the pixels of ``ref`` (4, H, W) that no light gives -- S0 < 0, or a degree of
    polarization sqrt(S1^2 + S2^2 + S3^2) / S0 > 1 -- beyond 5 sigma (``sigma`` (4, H, W); without it,
    beyond float32 rounding), and ``sigma_bad`` (pixels whose sigma is negative, zero or NaN).  Each
    kind is one :class:`ReferenceDataWarning` naming ``what`` and the share of its pixels."""
    import warnings

    ref = np.asarray(ref, np.float64)
    peak = float(np.abs(ref[0]).max()) if ref.size else 0.0
    if sigma is None:                                  # a rendering: float32 rounding only
        tol0 = tolp = 1e-5 * np.abs(ref[0]) + 1e-7 * peak
    else:
        sig = np.nan_to_num(np.abs(np.asarray(sigma, np.float64)))
        tol0, tolp = 5.0 * sig[0], 5.0 * np.sqrt((sig ** 2).sum(axis=0))   # 5 sigma: no false alarm in 1e6 px
    negative = ref[0] < -tol0
    kinds = [(negative, "a negative S0 beyond the noise"),
             (~negative & (np.sqrt((ref[1:] ** 2).sum(axis=0)) - ref[0] > tolp),
              "a degree of polarization > 1 beyond the noise (sqrt(S1^2 + S2^2 + S3^2) > S0)"),
             (np.zeros(ref.shape[1:], bool) if sigma_bad is None else sigma_bad, "a negative, zero or NaN sigma")]
    for bad, why in kinds:
        if bad.any():
            warnings.warn(f"{what}: {100 * bad.mean():.3g} % of the pixels ({int(bad.sum())} of {bad.size}) have "
                          f"{why}: no light gives that; they are left out", ReferenceDataWarning, stacklevel=3)
    return kinds[0][0] | kinds[1][0] | kinds[2][0]


def _as_layers(data, measured):
    """(stokes dict, sigma dict, mask or None, colours) from any accepted form of camera data."""
    if isinstance(data, (str, Path)):
        from hyde_bsdf.io.stokes_exr import read_camera_stokes

        d = read_camera_stokes(data)
        return d["stokes"], d["sigma"], d["mask"], d["colours"], str(data)
    if isinstance(data, StokesEstimate):
        return dict(data.stokes), dict(data.sigma), data.mask, None, "the Stokes estimate"
    if isinstance(data, dict):
        stokes = {k: v for k, v in data.items() if k in STOKES}
        return stokes, dict(data.get("sigma") or {}), data.get("mask"), data.get("colours"), "the Stokes data"
    arr = np.asarray(data, np.float64)
    if arr.ndim not in (3, 4) or not 1 <= arr.shape[0] <= 4:
        raise UsageError(f"a Stokes array must be (M, H, W) or (M, H, W, C) with M = 1..4 components, got {arr.shape}")
    names = tuple(measured) if measured is not None else STOKES[: arr.shape[0]]
    if len(names) != arr.shape[0]:
        raise UsageError(f"the Stokes array has {arr.shape[0]} components but measured names {list(names)}")
    return {n: arr[i] for i, n in enumerate(names)}, {}, None, None, "the Stokes array"


def _reduce(arr, colours, channel, what):
    """(H, W, C) or (H, W) -> (H, W) by ``channel``; also returns the weights used."""
    a = np.asarray(arr, np.float64)
    if a.ndim == 2:
        return a, np.ones(1)
    C = a.shape[2]
    colours = tuple(colours) if colours else (("R", "G", "B") if C == 3 else tuple(str(i) for i in range(C)))
    if C == 1:
        return a[..., 0], np.ones(1)
    if channel == "Y" and colours == ("R", "G", "B"):
        w = np.asarray(Y_WEIGHTS)
        return a @ w, w
    if channel not in colours:
        raise UsageError(f"{what}: channel {channel!r} is not among its channels {list(colours)}; pick one of them"
                         f"{' or Y (luminance of R, G, B)' if colours == ('R', 'G', 'B') else ''}")
    w = np.zeros(C)
    w[colours.index(channel)] = 1.0
    return a @ w, w


def camera_reference(data, *, channel: str = "Y", measured=None, noise=None, analysis=None) -> dict:
    """The inverse's reference from camera data (see the module docstring).

    Returns ``{"reference": (4, H, W), "measured": names, "sigma": (4, H, W) or None, "mask": (H, W)
    bool or None}``; sigma is 0 on unmeasured components.  ``noise`` + ``analysis``: see
    :func:`~hyde_bsdf.model.polarimetry.stokes_sigma` (used only when the data carry no sigma)."""
    stokes, sigma, mask, colours, what = _as_layers(data, measured)
    if "S0" not in stokes:
        raise UsageError(f"{what} has no S0: the intensity is needed (got {sorted(stokes)})")
    names = tuple(c for c in STOKES if c in stokes)
    shape = np.shape(stokes["S0"])
    for c in names:
        if np.shape(stokes[c]) != shape or (c in sigma and np.shape(sigma[c]) != shape):
            raise UsageError(f"{what}: {c} has shape {np.shape(stokes[c])}, S0 {shape}; all components alike")
    if sigma and set(sigma) != set(names):
        raise UsageError(f"{what}: sigma is given for {sorted(sigma)} but the components are {list(names)}")
    if not sigma and noise is not None:
        stack = np.array([np.asarray(stokes[c], np.float64) for c in names])
        est = stokes_sigma(stack, noise, analysis)
        sigma = {c: est[i] for i, c in enumerate(names)}
    H, W = shape[:2]
    ref = np.zeros((4, H, W))
    sig = np.zeros((4, H, W)) if sigma else None
    sigma_bad = np.zeros((H, W), bool)
    for c in names:
        i = STOKES.index(c)
        ref[i], w = _reduce(stokes[c], colours, channel, what)
        if sig is not None:
            s = np.asarray(sigma[c], np.float64)
            bad = ~(s > 0) | ~np.isfinite(s)                       # NaN, negative or zero
            sigma_bad |= bad if s.ndim == 2 else bad[..., w > 0].any(axis=-1)
            sig[i] = s if s.ndim == 2 else np.sqrt(s ** 2 @ w ** 2)     # independent channels
    if mask is not None and np.shape(mask) != (H, W):
        raise UsageError(f"{what}: the mask is {np.shape(mask)[::-1]}, the image {W}x{H}")
    mask = None if mask is None else as_mask(mask, f"{what}: its mask")
    # NaN and an absurd scale are refusals: before any data warning
    check_reference_scale(ref, shorten(what) if isinstance(data, (str, Path)) else what)
    inside = np.ones((H, W), bool) if mask is None else mask      # (sigma is 0 where the data mask a pixel)
    bad = impossible_pixels(ref, sig, what, sigma_bad & inside) & inside
    if bad.any():
        mask = ~bad if mask is None else mask & ~bad
    return {"reference": ref, "measured": names, "sigma": sig, "mask": mask}


def camera_observation(scene, data, *, sensor: int = 0, weight: float = 1.0, mask=None, **kwargs) -> Observation:
    """An :class:`~hyde_bsdf.inverse.observations.Observation` of ``scene``'s sensor from camera data
    (:func:`camera_reference`; ``kwargs`` go there).  The loss mask is the interior of the lit object
    (:func:`~hyde_bsdf.inverse.loss.interior_mask`; with sigma, lit means S0 > 3 sigma(S0): a camera's
    background is noise around zero), the data's own mask and ``mask``, together."""
    ref = camera_reference(data, **kwargs)
    s0 = ref["reference"][0]
    if ref["sigma"] is not None:          # a camera's background is noise around 0: lit means S0 > 3 sigma
        s0 = np.where(s0 > 3.0 * ref["sigma"][0], s0, 0.0)
    m = interior_mask(s0)
    for extra in (ref["mask"], mask):
        if extra is not None:
            if np.shape(extra) != m.shape:
                raise UsageError(f"mask is {np.shape(extra)[::-1]} but the reference is {m.shape[1]}x{m.shape[0]}")
            m &= as_mask(extra)
    return Observation(scene, ref["reference"], sensor=sensor, mask=m, weight=weight, measured=ref["measured"],
                       sigma=ref["sigma"])


def calibrated_observations(base, cameras, lights, data, *, spp: int = 4, **kwargs) -> list:
    """Observations of a calibrated rig: one scene per light (:func:`~hyde_bsdf.render.camera.calibrated_scene`:
    the sample of ``base`` -- an XML file or a scene dict -- seen by every camera of ``cameras``, lit
    by that light), and per light and camera the camera data ``data[light][camera]`` (any form
    :func:`camera_reference` accepts; ``kwargs`` go there).  ``cameras``: a list of
    :class:`~hyde_bsdf.render.camera.Calibration` or a camera JSON path; ``lights``: emitter dicts or a
    light JSON path.  Returns the observations, light-major."""
    from hyde_bsdf.render.camera import calibrated_scene, load_cameras, load_lights

    cameras = load_cameras(cameras) if isinstance(cameras, (str, Path)) else list(cameras)
    lights = load_lights(lights) if isinstance(lights, (str, Path)) else list(lights)
    if len(data) != len(lights) or any(len(row) != len(cameras) for row in data):
        raise UsageError(f"camera data: need {len(lights)} light(s) x {len(cameras)} camera(s) of Stokes data, got "
                         f"{[len(row) for row in data]} per light")
    out = []
    for j, light in enumerate(lights):
        scene = calibrated_scene(base, cameras, light, spp=spp)
        for i, cam in enumerate(cameras):
            o = camera_observation(scene, data[j][i], sensor=i, **kwargs)
            if o.reference.shape[1:] != (cam.height, cam.width):
                raise UsageError(f"camera data for light {j}, camera {i} is {o.reference.shape[2]}x{o.reference.shape[1]} "
                                 f"but the calibration says {cam.width}x{cam.height}")
            out.append(o)
    return out


def observations_from_files(scene, cameras, lights, references, *, masks=None, spp: int = 4,
                            channel: str = "Y") -> list:
    """What ``invert --maps --scene SAMPLE.xml --camera CAMERA.json --light LIGHT.json --reference ...``
    builds: the calibrated observations (:func:`calibrated_observations`) of the sample ``scene`` (an XML
    file holding no sensor or emitter) with the Stokes EXRs ``references`` given light-major (for each
    light, one per camera) and optional ``masks`` (arrays (H, W), one per reference).  Every file is
    checked before any rendering (:func:`camera_files`); mistakes are UsageErrors naming the file."""
    cams, lts, data = camera_files(cameras, lights, references, masks=masks, channel=channel)
    return calibrated_observations(scene, cams, lts, [[{**_stokes_dict(d)} for d in row] for row in data], spp=spp)


def camera_files(cameras, lights, references, *, masks=None, channel: str = "Y"):
    """(cameras, lights, data): the camera and light JSON files read, and the references (Stokes EXRs,
    light-major) as :func:`camera_reference` results, light by light, with ``masks`` applied; each
    reference checked against its camera's image size."""
    from hyde_bsdf.render.camera import load_cameras, load_lights

    cams, lts = load_cameras(cameras), load_lights(lights)
    refs = [str(r) for r in references]
    if len(refs) != len(cams) * len(lts):
        raise UsageError(f"`cameras` has {len(cams)} camera(s) and `lights` {len(lts)} light(s): give "
                         f"{len(cams) * len(lts)} `references` files, light-major (for each light, one per camera); "
                         f"got {len(refs)}")
    data = [[camera_reference(refs[j * len(cams) + i], channel=channel) for i in range(len(cams))]
            for j in range(len(lts))]
    for j in range(len(lts)):
        for i, cam in enumerate(cams):
            h, w = data[j][i]["reference"].shape[1:]
            if (w, h) != (cam.width, cam.height):
                raise UsageError(f"`references` {refs[j * len(cams) + i]!r} is {w}x{h} px but camera {i} of `cameras` is "
                                 f"{cam.width}x{cam.height} (a DoFP camera's super-pixel images need \"binning\": 2)")
    if masks is not None:
        for k, m in enumerate(masks):
            j, i = divmod(k, len(cams))
            d = data[j][i]
            m = as_mask(m, f"the mask of `references` {refs[k]!r}")
            d["mask"] = m if d["mask"] is None else d["mask"] & m
    return cams, lts, data


def _stokes_dict(ref: dict) -> dict:
    """A :func:`camera_reference` result as the dict form :func:`camera_reference` accepts (luminance, mono)."""
    names = ref["measured"]
    idx = [STOKES.index(c) for c in names]
    out = {c: ref["reference"][i] for c, i in zip(names, idx)}
    if ref["sigma"] is not None:
        out["sigma"] = {c: ref["sigma"][i] for c, i in zip(names, idx)}
    if ref["mask"] is not None:
        out["mask"] = ref["mask"]
    return out
