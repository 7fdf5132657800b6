"""Observations for texture-valued (SVBRDF) inversion: parameter keys, Stokes renders of one
sensor, the :class:`Observation` record, the UV-coverage pass, and the validation's plane scene.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from hyde_bsdf.errors import UsageError, shorten
from hyde_bsdf.inverse.loss import as_mask, channel_names as film_channels, interior_mask, stokes_images
from hyde_bsdf.inverse.scalar import RANGES, _unique_key
from hyde_bsdf.model.parameters import ALPHA, INVERSE_K_LOG_FLOOR, INVERSE_SCALE

__all__ = ["MAP_PARAMETERS", "MAP_VARIANT", "map_keys", "film_channels", "render_stokes", "render_stokes_np",
           "Observation", "texel_coverage", "pixel_texels", "example_maps", "plane_scene_dict", "VIEW_AZIMUTHS", "LIGHTS"]


#: texture-valued parameters: name -> (traverse-key suffixes, accepted range).  ``alpha`` is the
#: Beckmann alpha (roughconductor's meaning and key; hyde's ``alpha`` texture), ``rms_slope`` hyde's
#: own roughness texture (alpha = sqrt(2) rms_slope), ``eta``, ``k`` the index (Mitsuba's n + ik),
#: ``specular_reflectance`` the plugin's multiplier of the whole BSDF (an unknown per-texel scale).
MAP_PARAMETERS = {
    "alpha": ((".alpha.data", ".alpha.value"), ALPHA.bounds),
    "rms_slope": ((".rms_slope.data", ".rms_slope.value", ".rms_slope"), RANGES["rms_slope"]),
    "eta": ((".eta.data", ".eta.value"), RANGES["eta"]),
    "k": ((".k.data", ".k.value"), (INVERSE_K_LOG_FLOOR, RANGES["k"][1])),
    # a multiplier of the whole BSDF: an unknown albedo or an uncalibrated light, per texel
    "specular_reflectance": ((".specular_reflectance.data", ".specular_reflectance.value"), INVERSE_SCALE.bounds),
}
#: the variant of the SVBRDF validation, tests and benchmark: monochromatic polarized.  The
#: scenes there have white lights and a wavelength-independent index, so one wavelength holds
#: all the information; the spectral variant only adds wavelength-sampling noise and 2x time.
MAP_VARIANT = "llvm_ad_mono_polarized"


def map_keys(params, names=("alpha",), prefix: str | None = None) -> dict:
    """Map texture parameter names (:data:`MAP_PARAMETERS`) to ``mi.traverse`` keys.

    A texture-valued parameter (``<texture type="bitmap">``) has the key ``...NAME.data``
    (a TensorXf of shape (rows, columns, 1); row r holds v in [r, r + 1) / rows), a constant one
    ``...NAME.value``.  ``prefix`` (e.g. ``"plane.bsdf"``) picks one BSDF when the scene has several.
    """
    out = {}
    for name in names:
        if name not in MAP_PARAMETERS:
            raise UsageError(f"parameter names must be from {tuple(MAP_PARAMETERS)}, got {shorten(name)}")
        # suffixes tried in order: the texture's data first, then a constant's value
        out[name] = _unique_key(params, name, [(s,) for s in MAP_PARAMETERS[name][0]], prefix)
    return out


def render_stokes(scene, sensor: int = 0, spp: int = 16, seed: int = 0, params=None, names=None) -> list:
    """Luminance S0..S3 tensors (H, W) of one sensor's render (differentiable when ``params`` given).

    ``names``: the film's channel names (:func:`~hyde_bsdf.inverse.loss.channel_names`), given by a caller that renders
    inside ``dr.freeze`` (reading them back from the film there is a host operation it refuses)."""
    import mitsuba as mi

    seed = seed if isinstance(seed, mi.UInt32) else int(seed)      # UInt32: an opaque seed (dr.freeze)
    img = (mi.render(scene, params, sensor=int(sensor), spp=int(spp), seed=seed) if params is not None
           else mi.render(scene, sensor=int(sensor), spp=int(spp), seed=seed))
    if names is None:
        names = [f.name for f in scene.sensors()[int(sensor)].film().bitmap().struct_()]
    return stokes_images(img, names)


def render_stokes_np(scene, sensor: int = 0, spp: int = 64, seed: int = 0) -> np.ndarray:
    """:func:`render_stokes` as a float64 array (4, H, W) (references)."""
    return np.array([np.asarray(s, dtype=np.float64) for s in render_stokes(scene, sensor, spp, seed)])


@dataclass
class Observation:
    """One reference image: a scene, the index of its sensor, the reference Stokes images.

    ``reference``: luminance S0..S3, shape (4, H, W) (:func:`render_stokes_np` or a Stokes EXR
    through ``Y_WEIGHTS``).  ``mask``: bool (H, W) of the pixels the loss uses (default
    :func:`interior_mask` of S0: lit pixels away from silhouettes).  ``weight``: this image's
    share of the data loss.  ``measured``: the Stokes components the camera measured (a linear
    polarization camera: ("S0", "S1", "S2")); the others are not in the loss and their reference
    values are ignored.  ``sigma``: the reference's noise standard deviation per component, (4,) or
    (4, H, W) (e.g. from :mod:`hyde_bsdf.model.polarimetry`): the loss's weights (1 / sigma^2) and the
    noise of the standard errors (:class:`~hyde_bsdf.inverse.loss.StokesLoss`); :func:`camera_observation`
    builds one from camera data.  Several observations may share a scene (one per sensor) or use
    different scenes (e.g. one per light: one light per render avoids the light-selection noise
    of a scene with several lights); the fitted textures are written into every scene.
    """

    scene: object
    reference: np.ndarray
    sensor: int = 0
    mask: np.ndarray | None = None
    weight: float = 1.0
    measured: tuple = ("S0", "S1", "S2", "S3")
    sigma: np.ndarray | None = None


def texel_coverage(obs: Observation, shape, prefix: str | None = None, sub: int = 4) -> np.ndarray:
    """Samples per texel of a (rows, columns) map on the target shape that ``obs``'s masked pixels see.

    Casts ``sub`` x ``sub`` camera rays per pixel of the loss mask (what the loss uses), keeps those
    whose first hit is the shape carrying the target BSDF (``prefix``, default: the one shape whose
    BSDF has a texture parameter) and bins their UV into texels as the nearest-neighbour bitmap
    lookup does (column = floor(u W), row = floor(v H); ``to_uv`` is assumed identity).
    Returns counts (rows, columns); a texel with 0 is never seen, so it carries no information.
    """
    pixel, texel = pixel_texels(obs, shape, prefix, sub)
    return np.bincount(texel, minlength=int(shape[0]) * int(shape[1])).reshape(tuple(shape))


def pixel_texels(obs: Observation, shape, prefix: str | None = None, sub: int = 4, edges: bool = False):
    """The (pixel, texel) pair of every camera sub-sample of :func:`texel_coverage` that hits the target
    shape: two int arrays, pixel = row * W + column of the film, texel = row * columns + column of the
    map.  ``sub`` x ``sub`` sub-samples per masked pixel; a pixel's share of texel t is its count of
    pairs (pixel, t) / sub**2.  ``edges=True`` puts the outer sub-samples on the pixel's border
    (inset by 1e-3 pixel) instead of at the centres of a sub x sub grid: a pixel whose sub-samples all
    land in one texel then lies inside it entirely (its corners do, and a texel is convex), which is
    how :mod:`hyde_bsdf.inverse.uncertainty` picks the pixels that depend on one texel only (with the
    centred grid, pixels reaching up to 1/(2 sub) of their width into the next texel passed, and
    carried its value and its sampling noise)."""
    import mitsuba as mi

    scene = obs.scene
    sensor = scene.sensors()[int(obs.sensor)]
    W, H = sensor.film().crop_size()
    mask = _obs_mask(obs)
    ys, xs = np.nonzero(mask)
    o = np.linspace(1e-3, 1.0 - 1e-3, sub) if edges else (np.arange(sub) + 0.5) / sub
    ox, oy = np.meshgrid(o, o)
    px = (xs[:, None] + ox.ravel()[None, :]).ravel() / W
    py = (ys[:, None] + oy.ravel()[None, :]).ravel() / H
    pix = np.repeat(ys * W + xs, sub * sub)
    target = _target_shape(scene, prefix)
    # the film positions go in as Python lists: Dr.Jit then owns copies.  Arrays made straight from
    # NumPy memory stay referenced by the sensor's state and are released later through a host
    # callback, which a later dr.freeze recording cannot hold (Dr.Jit aborts the process)
    ray, _ = sensor.sample_ray(mi.Float(0.0), mi.Float(0.5), mi.Point2f(mi.Float(px.tolist()), mi.Float(py.tolist())),
                               mi.Point2f(0.5, 0.5))
    si = scene.ray_intersect(ray)
    hit = np.array(si.is_valid() & (si.shape == mi.ShapePtr(target)), dtype=bool)
    uv = np.array([np.array(si.uv.x, dtype=np.float64), np.array(si.uv.y, dtype=np.float64)])
    rows, cols = int(shape[0]), int(shape[1])
    c = np.clip(np.floor(uv[0][hit] * cols).astype(int), 0, cols - 1)
    r = np.clip(np.floor(uv[1][hit] * rows).astype(int), 0, rows - 1)
    return pix[hit], r * cols + c


def _target_shape(scene, prefix):
    """The shape whose BSDF is the target (``prefix`` "ID.bsdf" names it; default: the only textured one)."""
    shapes = list(scene.shapes())
    if prefix is not None:
        sid = prefix.split(".")[0]
        found = [s for s in shapes if s.id() == sid]
    else:
        import mitsuba as mi

        params = mi.traverse(scene)
        owners = {k.split(".")[0] for k in params.keys() if k.endswith(".data") and ".bsdf." in k}
        found = [s for s in shapes if s.id() in owners]
    if len(found) != 1:
        raise UsageError(f"need exactly one shape carrying the textured BSDF"
                         f"{'' if prefix is None else ' ' + shorten(prefix)}; found "
                         f"{shorten([s.id() for s in found])} (name it with prefix='ID.bsdf')")
    return found[0]


def _obs_mask(obs: Observation) -> np.ndarray:
    ref = np.asarray(obs.reference, dtype=np.float64)
    mask = interior_mask(ref[0]) if obs.mask is None else as_mask(obs.mask, "the observation's mask")
    if mask.shape != ref.shape[1:]:
        raise UsageError(f"mask shape {mask.shape} differs from the reference's {ref.shape[1:]}")
    return mask


# the SVBRDF scene: a textured plane, three views in one batch sensor, one point light per scene

def example_maps(n: int = 32) -> np.ndarray:
    """The validation's Beckmann alpha map (n x n): a smooth gradient 0.15 -> 0.45 along u plus a
    sharp-edged square (alpha 0.6) at u in [0.2, 0.5), v in [0.45, 0.75)."""
    u = (np.arange(n) + 0.5) / n
    U, V = np.meshgrid(u, u)
    alpha = 0.15 + 0.3 * U + 0.05 * np.sin(2 * np.pi * V)
    alpha[(U >= 0.2) & (U < 0.5) & (V >= 0.45) & (V < 0.75)] = 0.6
    return alpha


def _orbit(azimuth_deg, elevation_deg, distance):
    az, el = math.radians(azimuth_deg), math.radians(elevation_deg)
    return [distance * math.cos(el) * math.cos(az), distance * math.cos(el) * math.sin(az),
            distance * math.sin(el)]


#: camera azimuths (deg) of the three views (elevation 55 deg, 4 units from the plane's centre)
VIEW_AZIMUTHS = (0.0, 120.0, 240.0)
#: point lights (azimuth, elevation deg, distance), one per scene
LIGHTS = ((60.0, 60.0, 5.0), (240.0, 60.0, 5.0))


def plane_scene_dict(alpha, *, bsdf: str = "hyde", eta: float = 1.5, k: float = 3.0, light: int = 0,
                     res: int = 96, spp: int = 4, diffuse: str = "paper", views=VIEW_AZIMUTHS,
                     shadowing: str | None = None) -> dict:
    """A 2 x 2 plane (shape id ``plane``, UV = (x + 1, y + 1) / 2) with the roughness map ``alpha``
    (Beckmann alpha, rows along v, nearest-neighbour lookup) and a constant index, seen by
    ``len(views)`` cameras side by side in one ``batch`` sensor (film ``len(views) * res`` x ``res``),
    lit by point light ``LIGHTS[light]``.  ``bsdf``: ``hyde`` (``shadowing`` passed on when given) or
    ``roughconductor`` (Beckmann, the same alpha, eta, k).  Direct light only (``stokes`` around ``path``, max_depth 2)."""
    import mitsuba as mi

    tex = {"type": "bitmap", "bitmap": mi.Bitmap(np.asarray(alpha, np.float32)[..., None]), "raw": True,
           "filter_type": "nearest"}
    if bsdf == "hyde":
        material = {"type": "hyde", "alpha": tex, "eta": float(eta), "k": float(k), "diffuse": diffuse}
        if shadowing is not None:
            material["shadowing"] = shadowing
    elif bsdf == "roughconductor":
        material = {"type": "roughconductor", "distribution": "beckmann", "alpha": tex,
                    "eta": float(eta), "k": float(k)}
    else:
        raise UsageError(f"bsdf must be 'hyde' or 'roughconductor', got {shorten(bsdf)}")
    # mono variants store luminance (saying so avoids Mitsuba's warning that it switched the format)
    fmt = {"pixel_format": "luminance"} if mi.is_monochromatic else {}
    film = lambda w: {"type": "hdrfilm", "width": int(w), "height": int(res), "rfilter": {"type": "box"}, **fmt}
    cams = {f"view{i}": {"type": "perspective", "fov": 40, "film": film(res),
                         "to_world": mi.ScalarTransform4f().look_at(origin=_orbit(az, 55.0, 4.0),
                                                                    target=[0, 0, 0], up=[0, 0, 1])}
            for i, az in enumerate(views)}
    la, le, ld = LIGHTS[light]
    return {"type": "scene",
            "integrator": {"type": "stokes", "integrator": {"type": "path", "max_depth": 2}},
            "sensor": {"type": "batch", **cams, "film": film(len(views) * res),
                       "sampler": {"type": "multijitter", "sample_count": int(spp)}},
            "plane": {"type": "rectangle", "bsdf": material},
            "light": {"type": "point", "position": _orbit(la, le, ld),
                      "intensity": {"type": "spectrum", "value": 30.0}}}
