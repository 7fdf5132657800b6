"""Mitsuba sensors and emitters from a calibrated camera and measured lights.

Conventions -- stated once here, converted at this boundary:

* **Camera (input)**: the computer-vision pinhole model of OpenCV and most calibration tools.
  World-to-camera pose ``R`` (3 x 3 rotation), ``t`` (3,): a world point X has camera coordinates
  ``Xc = R X + t``; camera axes x right, y down, z forward (along the optical axis).  Intrinsics
  ``fx, fy`` (focal length in pixels; square pixels required, ``fx = fy`` within 0.1 %), principal
  point ``cx, cy`` in pixels with **pixel centres at integer coordinates** (the top-left pixel's
  centre is (0, 0); OpenCV's convention), image ``width, height``.  The pixel of X is
  ``u = fx Xc_x / Xc_z + cx``, ``v = fy Xc_y / Xc_z + cy`` (:meth:`Calibration.project`).
* **Distortion**: refused.  A calibration with non-zero distortion coefficients must have its
  images undistorted first (e.g. OpenCV's ``undistort`` with the same K) and then be given with
  ``distortion`` absent or all zeros: Mitsuba's ``perspective`` sensor is an ideal pinhole.
* **Mitsuba (output)**: the ``perspective`` sensor looks along its local +z with local +x to the
  image's *left* and +y *up* (its film's column 0 is at local +x, row 0 at +y).  The CV camera frame
  is therefore Mitsuba's turned 180 deg about z: ``to_world = [R^T diag(-1, -1, 1) | C]`` with the
  camera centre C = -R^T t -- a rigid transform, no mirror.  ``fov`` = 2 atan(width / (2 fx)) along
  x; the principal point becomes Mitsuba's ``principal_point_offset_x/y`` (fractions of the film,
  added to the film position of a ray): ``0.5 - (cx + 0.5) / width`` and ``0.5 - (cy + 0.5) / height``.
  tests/test_camera.py renders a marker at a known 3-D point and finds it on the predicted pixel
  (within 0.5 px).
* **Lights** (JSON): ``{"type": "point", "position": [x, y, z], "intensity": I}`` (world units;
  I in W/sr, Mitsuba's radiant intensity) or ``{"type": "directional", "towards_light": [x, y, z],
  "irradiance": E}`` -- the unit vector from the scene *towards* the light, as a mirror-sphere
  calibration measures it (Mitsuba's ``direction`` is the opposite, the light's travel).  Optional
  ``"polarizer": ANGLE`` (and ``"retarder": ANGLE``, a quarter-wave plate after it) put sheets on the
  light facing ``"aim"`` (default the origin); angles as in :mod:`hyde_bsdf.inverse.acquisition`
  (0 deg: horizontal, perpendicular to world z and the light's axis).

File formats (JSON; :func:`load_cameras`, :func:`load_lights`)::

    {"width": 64, "height": 48, "fx": 60, "fy": 60, "cx": 31.5, "cy": 23.5,
     "R": [[1, 0, 0], [0, 1, 0], [0, 0, 1]], "t": [0, 0, 4], "distortion": [0, 0, 0, 0, 0]}

(``"K": [[fx, 0, cx], [0, fy, cy], [0, 0, 1]]`` may replace fx, fy, cx, cy; ``"binning": 2`` says the
Stokes images are a DoFP camera's super-pixel grid while the intrinsics are the raw sensor's
(:meth:`Calibration.binned`); ``{"cameras": [...]}`` holds several) and ``{"lights": [{...}, ...]}`` (or one light object).  Mistakes raise
:class:`~hyde_bsdf.errors.UsageError` naming the file and the key.
"""
from __future__ import annotations

import json
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from hyde_bsdf.errors import UsageError

__all__ = ["Calibration", "Light", "load_cameras", "load_lights", "light_dict", "light_spec", "calibrated_sensors",
           "calibrated_scene"]

#: the horizontal field of view a calibration may give, deg (Mitsuba's perspective sensor needs (0, 180))
FOV_RANGE = (1e-3, 179.0)
#: Mitsuba camera-local axes expressed in the CV camera frame: x left, y up, z forward
CV_TO_MITSUBA = np.diag([-1.0, -1.0, 1.0])


@dataclass(frozen=True)
class Calibration:
    """One calibrated pinhole camera (see the module docstring for the conventions)."""

    width: int
    height: int
    fx: float
    fy: float
    cx: float
    cy: float
    R: np.ndarray
    t: np.ndarray

    @classmethod
    def from_dict(cls, d: dict, where: str = "camera") -> "Calibration":
        """Build and check one camera from a JSON object (``where`` names it in messages)."""
        if not isinstance(d, dict):
            raise UsageError(f"{where}: a camera is a JSON object with width, height, fx, fy, cx, cy, R, t")
        if "K" in d:
            K = _matrix(d["K"], (3, 3), f"{where}: K")
            if abs(K[0, 1]) > 1e-9 or np.any(np.abs(K[2] - [0, 0, 1]) > 1e-9) or abs(K[1, 0]) > 1e-9:
                raise UsageError(f"{where}: K must be [[fx, 0, cx], [0, fy, cy], [0, 0, 1]] (no skew)")
            d = {**d, "fx": K[0, 0], "fy": K[1, 1], "cx": K[0, 2], "cy": K[1, 2]}
        missing = [k for k in ("width", "height", "fx", "fy", "cx", "cy", "R", "t") if k not in d]
        if missing:
            raise UsageError(f"{where}: missing {missing} (intrinsics fx, fy, cx, cy in pixels or K; "
                             f"world-to-camera R, t; image width, height)")
        dist = np.asarray(d.get("distortion", []) or [], np.float64).ravel()
        if np.any(dist != 0):
            raise UsageError(f"{where}: non-zero distortion {dist.tolist()}; undistort the images with the same "
                             f"K first and give distortion as zeros (the renderer is an ideal pinhole)")
        w, h = d["width"], d["height"]
        if not all(isinstance(v, int) and v >= 1 for v in (w, h)):
            raise UsageError(f"{where}: width and height must be integers >= 1, got {w!r}, {h!r}")
        fx, fy, cx, cy = (_number(d[k], f"{where}: {k}") for k in ("fx", "fy", "cx", "cy"))
        if not (fx > 0 and fy > 0):
            raise UsageError(f"{where}: fx, fy must be > 0 pixels, got {fx}, {fy}")
        if abs(fx / fy - 1.0) > 1e-3:
            raise UsageError(f"{where}: fx = {fx:g} and fy = {fy:g} differ by more than 0.1 %; resample the images "
                             f"to square pixels (the renderer's pixels are square)")
        fov = math.degrees(2.0 * math.atan(w / (2.0 * fx)))
        if not FOV_RANGE[0] <= fov <= FOV_RANGE[1]:
            raise UsageError(f"{where}: fx = {fx:g} px over a width of {w} px is a field of view of {fov:.6g} deg; a "
                             f"pinhole camera's is in [{FOV_RANGE[0]:g}, {FOV_RANGE[1]:g}] deg (fx in pixels, "
                             f"{w / (2 * math.tan(math.radians(FOV_RANGE[1] / 2))):.3g} to "
                             f"{w / (2 * math.tan(math.radians(FOV_RANGE[0] / 2))):.3g} here)")
        R = _matrix(d["R"], (3, 3), f"{where}: R")
        if np.abs(R @ R.T - np.eye(3)).max() > 1e-6 or np.linalg.det(R) < 0:
            raise UsageError(f"{where}: R is not a rotation (R R^T = I, det R = +1 within 1e-6); give the "
                             f"world-to-camera rotation matrix")
        cal = cls(w, h, fx, fy, cx, cy, R, _matrix(d["t"], (3,), f"{where}: t"))
        binning = d.get("binning", 1)
        if binning not in (1, 2):
            raise UsageError(f"{where}: binning must be 1 or 2 (a DoFP camera's super-pixel grid), got {binning!r}")
        return cal.binned(2) if binning == 2 else cal

    def binned(self, b: int = 2) -> "Calibration":
        """The calibration of the image binned ``b`` x ``b`` (a DoFP camera's super-pixel Stokes image, b = 2):
        size and focal length / b; the centre of super-pixel i is raw coordinate b i + (b - 1) / 2, so
        c -> (c - (b - 1) / 2) / b."""
        if self.width % b or self.height % b:
            raise UsageError(f"binning {b}: the image {self.width}x{self.height} is not a multiple of {b}")
        o = (b - 1) / 2.0
        return Calibration(self.width // b, self.height // b, self.fx / b, self.fy / b, (self.cx - o) / b,
                           (self.cy - o) / b, self.R, self.t)

    @property
    def center(self) -> np.ndarray:
        """The camera centre in world coordinates, -R^T t."""
        return -self.R.T @ self.t

    def project(self, points) -> np.ndarray:
        """Pixel coordinates (N, 2) (u right, v down; pixel centres at integers) of world points (N, 3)."""
        Xc = np.atleast_2d(np.asarray(points, np.float64)) @ self.R.T + self.t
        return np.stack([self.fx * Xc[:, 0] / Xc[:, 2] + self.cx, self.fy * Xc[:, 1] / Xc[:, 2] + self.cy], axis=1)

    def to_world(self) -> np.ndarray:
        """Mitsuba's camera-to-world matrix (4, 4): [R^T diag(-1, -1, 1) | C]."""
        M = np.eye(4)
        M[:3, :3] = self.R.T @ CV_TO_MITSUBA
        M[:3, 3] = self.center
        return M

    def sensor_dict(self, *, spp: int = 16, film: dict | None = None, sampler: str = "independent") -> dict:
        """The Mitsuba ``perspective`` sensor of this camera (film ``width`` x ``height``, box filter,
        ``film`` entries added)."""
        import mitsuba as mi

        fov = math.degrees(2.0 * math.atan(self.width / (2.0 * self.fx)))
        fmt = {"pixel_format": "luminance"} if mi.is_monochromatic else {}
        return {"type": "perspective", "fov": fov, "fov_axis": "x",
                "principal_point_offset_x": 0.5 - (self.cx + 0.5) / self.width,
                "principal_point_offset_y": 0.5 - (self.cy + 0.5) / self.height,
                "to_world": mi.ScalarTransform4f(self.to_world().tolist()),
                "film": {"type": "hdrfilm", "width": self.width, "height": self.height,
                         "rfilter": {"type": "box"}, **fmt, **(film or {})},
                "sampler": {"type": sampler, "sample_count": int(spp)}}


def _number(v, what) -> float:
    if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
        raise UsageError(f"{what} must be a finite number, got {v!r}")
    return float(v)


def _matrix(v, shape, what) -> np.ndarray:
    try:
        a = np.asarray(v, np.float64)
    except (TypeError, ValueError):
        a = None
    if a is None or a.shape != shape or not np.isfinite(a).all():
        raise UsageError(f"{what} must be {'a 3 x 3 matrix' if len(shape) == 2 else 'a list of 3 numbers'} "
                         f"of finite numbers, got {v!r}")
    return a


def _read_json(path, what):
    """The JSON of ``path`` (a regular file of at most 1 MiB: the input gate), one line for what is not."""
    from hyde_bsdf.io.input_gate import check_input

    if not Path(path).exists():
        raise UsageError(f"{what} {str(path)!r}: no such file")
    path = check_input(path, what, limit=2**20, stdin=False)
    try:
        return json.loads(path.read_text())
    except RecursionError:                     # [[[[... 100,000 deep: Python's parser gives up
        raise UsageError(f"{what} {str(path)!r}: nested too deeply to be a calibration (JSON arrays or objects "
                         f"inside each other beyond Python's limit)") from None
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise UsageError(f"{what} {str(path)!r}: not readable JSON ({str(exc).splitlines()[0]})") from None


def load_cameras(path) -> list:
    """The :class:`Calibration` list of a camera JSON file (one camera object or ``{"cameras": [...]}``)."""
    d = _read_json(path, "camera file")
    items = d["cameras"] if isinstance(d, dict) and "cameras" in d else [d]
    if not isinstance(items, list) or not items:
        raise UsageError(f"camera file {str(path)!r}: 'cameras' must be a non-empty list")
    return [Calibration.from_dict(c, f"{path}: camera {i}" if len(items) > 1 else str(path)) for i, c in enumerate(items)]


@dataclass(frozen=True)
class Light:
    """One calibrated light: its Mitsuba ``emitter`` dict and, optionally, a linear polarizer (transmission
    axis ``polarizer`` deg) and a quarter-wave retarder after it (fast axis ``retarder`` deg) on it, as
    sheets facing the light's axis towards ``aim`` (0 deg: horizontal, perpendicular to world z and the
    axis -- s for a plane of incidence containing z, the acquisition design's convention)."""

    emitter: dict
    polarizer: float | None = None
    retarder: float | None = None
    aim: tuple = (0.0, 0.0, 0.0)
    sheet_size: float | None = None

    def sheets(self) -> dict:
        """The scene entries of the polarizer and retarder sheets (Mitsuba ``polarizer`` / ``retarder`` on
        ``rectangle`` shapes; they transmit with ``stokes`` + ``volpath``)."""
        import mitsuba as mi

        if self.polarizer is None:
            return {}
        aim = np.asarray(self.aim, np.float64)
        if self.emitter["type"] == "point":
            pos = np.asarray(self.emitter["position"], np.float64)
            D = float(np.linalg.norm(aim - pos))
            axis = (aim - pos) / D
            at = {"light_polarizer": pos + 0.10 * D * axis, "light_retarder": pos + 0.12 * D * axis}
            size = 0.15 * D if self.sheet_size is None else self.sheet_size
        else:
            axis = np.asarray(self.emitter["direction"], np.float64)
            at = {"light_polarizer": aim - 100.0 * axis, "light_retarder": aim - 90.0 * axis}
            size = 3.0 if self.sheet_size is None else self.sheet_size
        up = [0.0, 0.0, 1.0] if abs(axis[2]) < 0.999 else [0.0, 1.0, 0.0]
        out = {}
        for name, p in at.items():
            if name == "light_retarder" and self.retarder is None:
                continue
            bsdf = ({"type": "polarizer", "theta": float(self.polarizer)} if name == "light_polarizer" else
                    {"type": "retarder", "theta": float(self.retarder), "delta": 90.0})
            T = mi.ScalarTransform4f
            out[name] = {"type": "rectangle", "bsdf": bsdf,
                         "to_world": T().look_at(origin=p.tolist(), target=aim.tolist(), up=up) @ T().scale(size)}
        return out


def light_dict(d: dict, where: str = "light") -> dict:
    """The Mitsuba emitter of one light object (see the module docstring)."""
    return light_spec(d, where).emitter


def light_spec(d: dict, where: str = "light") -> Light:
    """One light object as a :class:`Light`: the emitter, and ``"polarizer"`` / ``"retarder"`` angles
    (deg), ``"aim"`` (the point the sheets face, default the origin) when the light is polarized."""
    kind = d.get("type") if isinstance(d, dict) else None
    if kind == "point":
        pos = _matrix(d.get("position"), (3,), f"{where}: position")
        em = {"type": "point", "position": pos.tolist(),
              "intensity": {"type": "spectrum", "value": _positive(d.get("intensity", 1.0), f"{where}: intensity")}}
    elif kind == "directional":
        v = _matrix(d.get("towards_light"), (3,), f"{where}: towards_light")
        n = float(np.linalg.norm(v))
        if not n > 0:
            raise UsageError(f"{where}: towards_light must be a non-zero vector")
        em = {"type": "directional", "direction": (-v / n).tolist(),
              "irradiance": {"type": "spectrum", "value": _positive(d.get("irradiance", 1.0), f"{where}: irradiance")}}
    else:
        raise UsageError(f"{where}: type must be 'point' (with position, intensity) or 'directional' (with "
                         f"towards_light, irradiance), got {kind!r}")
    pol, ret = d.get("polarizer"), d.get("retarder")
    if ret is not None and pol is None:
        raise UsageError(f"{where}: a retarder needs a polarizer before it (give \"polarizer\": ANGLE)")
    pol = None if pol is None else _number(pol, f"{where}: polarizer")
    ret = None if ret is None else _number(ret, f"{where}: retarder")
    aim = tuple(_matrix(d.get("aim", [0.0, 0.0, 0.0]), (3,), f"{where}: aim").tolist())
    if em["type"] == "point" and np.allclose(aim, em["position"]):
        raise UsageError(f"{where}: aim must differ from the light's position")
    return Light(em, pol, ret, aim)


def _positive(v, what) -> float:
    x = _number(v, what)
    if not x > 0:
        raise UsageError(f"{what} must be > 0, got {x}")
    return x


def load_lights(path) -> list:
    """The :class:`Light` list of a light JSON file (one light object or ``{"lights": [...]}``)."""
    d = _read_json(path, "light file")
    items = d["lights"] if isinstance(d, dict) and "lights" in d else [d]
    if not isinstance(items, list) or not items:
        raise UsageError(f"light file {str(path)!r}: 'lights' must be a non-empty list")
    return [light_spec(x, f"{path}: light {i}") for i, x in enumerate(items)]


def calibrated_sensors(cameras, **kwargs) -> dict:
    """{"camera0": sensor, ...} for a list of :class:`Calibration` (``kwargs``: :meth:`Calibration.sensor_dict`)."""
    return {f"camera{i}": c.sensor_dict(**kwargs) for i, c in enumerate(cameras)}


def calibrated_scene(base, cameras, light, *, spp: int = 16, film: dict | None = None):
    """A Mitsuba scene: the sample of ``base`` (an XML scene file, or a scene dict) with its integrator
    and shapes (their BSDFs and textures keep their ids, so ``mi.traverse`` keys stay), seen by the
    calibrated ``cameras`` (sensors 0..N-1 in order) and lit by ``light`` (a :class:`Light`, or a
    Mitsuba emitter dict).  ``base`` must hold no sensor and no emitter (UsageError): the calibration
    gives them, and one light per scene keeps the light-selection noise out of the renders.  A
    polarized light adds its sheets, which only ``volpath`` transmits: the integrator then becomes
    ``stokes`` around ``volpath`` (max_depth 2, direct light, as the acquisition design's)."""
    import mitsuba as mi

    if isinstance(base, dict):
        extra = [k for k, v in base.items() if isinstance(v, dict) and _plugin_kind(v.get("type")) in ("sensor", "emitter")]
        if extra:
            raise UsageError(f"the base scene holds {extra}: give the sample only (shapes, BSDFs, integrator); "
                             f"the calibration and the light file give the sensors and the emitters")
        d = {k: v for k, v in base.items() if k != "type"}
    else:
        path = Path(base)
        try:
            scene = mi.load_file(str(path))
        except Exception as exc:  # noqa: BLE001 -- a user's file: its first line says what is wrong
            raise UsageError(f"scene {str(path)!r}: {str(exc).strip().splitlines()[0][:200]}") from None
        if scene.emitters():
            raise UsageError(f"scene {str(path)!r} holds {len(scene.emitters())} emitter(s): give the sample only; "
                             f"the light file gives the emitters")
        d = {"integrator": scene.integrator()}
        for i, shape in enumerate(scene.shapes()):
            d[shape.id() or f"shape{i}"] = shape
    light = light if isinstance(light, Light) else Light(light)
    sheets = light.sheets()
    if sheets:
        d["integrator"] = {"type": "stokes", "integrator": {"type": "volpath", "max_depth": 2}}
    d = {"type": "scene", **d, **calibrated_sensors(cameras, spp=spp, film=film), "calibrated_light": light.emitter,
         **sheets}
    return mi.load_dict(d)


def _plugin_kind(name) -> str | None:
    """'sensor' / 'emitter' for Mitsuba's sensor and emitter plugin names, else None."""
    sensors = {"perspective", "thinlens", "orthographic", "radiancemeter", "irradiancemeter", "distant", "batch"}
    emitters = {"point", "directional", "area", "constant", "envmap", "spot", "projector", "directionalarea"}
    return "sensor" if name in sensors else "emitter" if name in emitters else None
