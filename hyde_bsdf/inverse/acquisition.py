"""Acquisition design for polarimetric material capture: which views, lights and polarizer states
to record a material sample under, and the Mitsuba scenes that render them.

A *configuration* is one picture: a distant (near-orthographic) Stokes camera (S0..S3 measured) along ``view``,
a directional light from ``light`` (both as (polar, azimuth) angles in degrees from the sample's
normal +z), optionally a linear polarizer in front of the light (transmission axis at ``polarizer``
degrees; 0 = s, the electric field perpendicular to the plane of incidence of a mirror pair in the
x-z plane, 90 = p) and a quarter-wave retarder after it (fast axis at ``retarder`` degrees).  With
a distant camera and a directional light every pixel sees nearly the same pair of directions, so
each configuration measures one facet (difference) angle beta = half the angle between the view
and the light, on every texel at once.  The camera is a ``perspective`` one ``CAMERA_DISTANCE`` = 30
units away with a field of view of 2 atan(extent / 30) (4 deg for the 2 x 2 plane: its rays lie
within 2 deg of the nominal view): Mitsuba's ``orthographic`` sensor cannot be recorded by
``dr.freeze`` (measured: "variable created before recording was started"), and an unfrozen step
costs ~50x more here.

Which Mueller elements a configuration constrains (the camera measures the output Stokes vector
S = M S_in; in the s/p basis of a mirror pair an isotropic surface has
M = [[A, B, 0, 0], [B, A, 0, 0], [0, 0, C, S], [0, 0, -S, C]] up to the lobe's off-plane terms):

=====================================  ==========================  =============================
illumination                           S_in                        elements measured (Stokes cam)
=====================================  ==========================  =============================
unpolarized                            (1, 0, 0, 0)                M00, M10, M20, M30 (A, B)
polarizer at 0 / 90 deg                (1, +-1, 0, 0) / 2          M00 +- M01, M10 +- M11 (A, B)
polarizer at 45 deg                    (1, 0, 1, 0) / 2            M00, M10, M22, M32 (A, B, C, S)
polarizer 0 deg + retarder at 45 deg   (1, 0, 0, +-1) / 2          M00, M10, M23, M33 (A, B, S, C)
=====================================  ==========================  =============================

An intensity camera (the S0-only loss) measures the first row only: M00 unpolarized, M00 +- M01
behind a polarizer at 0/90 deg, and nothing of C, S.

What each parameter set needs (N = a texel's unknowns; the numbers are median relative standard
errors over the validation's 8 x 8 maps from :func:`predicted_stderr` -- the Fisher information of
the NumPy evaluator at 1 % camera noise per Stokes component and 3.8 pixels per texel side, which
the rendered information matches to ~6 %):

* roughness alpha: the lobe's width -- at least two configurations whose half-vectors tilt from
  the normal by different angles (off-specular pairs; mirror pairs all see the lobe's peak, whose
  height 1/(pi alpha^2) a per-texel scale absorbs).  The presets' two off-specular pairs give
  0.2-0.4 %;
* dielectric index eta (k = 0): the degree of linear polarization B/A against beta, which does not
  depend on an intensity scale; one facet angle determines eta (one unpolarized mirror pair at 55
  deg + the 2 off-specular pairs: 0.14 %), two to five spanning 10-70 deg make it robust (0.12 %;
  near Brewster's angle B/A changes fastest).  Unpolarized light suffices;
* metal n and k: the reflectance A and the ratio B/A alone mix n and k (unpolarized mirror pairs at
  10-70 deg: n 25 %, k 13 % -- not determined); the retardance C, S (a polarizer at 45 deg, or
  circular light) separates them.  n is the weak one: it sets the metal's small absorption 1 - R
  and the phase, both weakly.  One mirror pair behind the 45 deg polarizer at any beta in 40-70 deg
  + the off-specular pairs: n 3.5-4 %, k 1.2 %; five at 10-70 deg: n 2.9 %
  (90th percentile 6.5 %); the ``"metal"`` preset (those five + circular light at 50 and 65 deg,
  9 pictures): n 2.5 % (5.3 %), k 0.6 %; adding polarizer states at 0 and 90 deg (19 pictures):
  n 1.9 % (3.5 %).  A circular state carries the same information as a 45 deg one (C and S swap
  roles), a state at 0 or 90 deg less.  The facet angles below 40 deg add little for n (a mirror
  pair at 10 deg alone: n 43 %), and those above ~75 deg foreshorten a texel to less than one pixel
  at 3.8 px per side, so they need more pixels per texel, not more pictures;
* a per-texel scale (``specular_reflectance``: an unknown albedo or an uncalibrated light): it
  multiplies every element alike, so it is determined by S0 and leaves only ratios -- B/A, C/A,
  S/A -- to determine the index.  With an intensity camera and unpolarized light the index then
  rests on the shape of M00 against beta alone, and on one facet angle (:func:`fixed_rig_acquisition`)
  not at all.

Presets (:func:`design_acquisition`): ``"dielectric"`` -- five mirror pairs at beta = 10, 25, 40,
55, 70 deg plus two off-specular pairs, unpolarized (7 pictures); ``"metal"`` -- the same mirror
pairs behind a polarizer at 45 deg, circular light (polarizer 0 deg + quarter-wave retarder at 45
deg) at beta = 50 and 65 deg, and the off-specular pairs unpolarized (9 pictures);
``polarizer_angles`` adds more states (e.g. (0, 45, 90)), ``retarder`` sets the circular states.
``camera="linear"`` (a linear polarization camera: S0, S1, S2 only) drops the row M3x from every
configuration's elements; its metal preset puts circular light on every mirror pair besides the 45 deg
polarizer (12 pictures), so that S (M23) still enters through S2; :func:`predicted_stderr` takes the
camera (docs/tutorials/capture.md tabulates what linear-only loses per parameter).

Scenes (:func:`acquisition_scene_dict`): Mitsuba's ``polarizer`` and ``retarder`` plugins are
sheets (rectangles) perpendicular to the light, 100 and 90 units out along it, outside every
camera's view (the cameras sit 30 units from the sample).  A point light behind such a sheet
renders black with ``stokes`` + ``path`` (its shadow rays are blocked), so a configuration with a
sheet uses ``stokes`` + ``volpath`` (which transmits through them); the others use ``path``.
"""
from __future__ import annotations

import math
import numbers
from dataclasses import dataclass, field

import numpy as np

from hyde_bsdf.errors import UsageError, shorten
from hyde_bsdf.model.polarimetry import retarder_mueller, simulate_capture

__all__ = ["Configuration", "Acquisition", "design_acquisition", "acquisition_scene_dict", "synthetic_observations", "example_material", "fixed_rig_acquisition",
           "PRESETS",
           "MIRROR_FACET_ANGLES", "OFF_SPECULAR", "CAMERAS", "METAL_RETARDER_FACET_ANGLES", "predicted_stderr"]

#: facet angles (deg) of the presets' mirror pairs
MIRROR_FACET_ANGLES = (10.0, 25.0, 40.0, 55.0, 70.0)
#: the presets' off-specular pairs: (view polar, light polar) in deg, in the x-z plane on opposite
#: sides (their half-vectors tilt by 10 and 12.5 deg from the normal)
OFF_SPECULAR = ((35.0, 15.0), (35.0, 60.0))
PRESETS = ("dielectric", "metal")
#: what the camera measures: ``"stokes"`` S0..S3 (a full-Stokes camera), ``"linear"`` S0..S2 (a linear
#: polarization camera: DoFP or rotating analyzer without retarder)
CAMERAS = ("stokes", "linear")
#: the Stokes components each camera measures (indices)
CAMERA_COMPONENTS = {"stokes": (0, 1, 2, 3), "linear": (0, 1, 2)}
#: facet angles (deg) of the ``"metal"`` preset's circular states (polarizer 0 deg + quarter-wave
#: retarder at 45 deg), where a metal's retardance carries n best for the pictures' cost
METAL_RETARDER_FACET_ANGLES = (50.0, 65.0)
#: distances (scene units) from the sample of the cameras, the polarizer and the retarder sheets
CAMERA_DISTANCE, POLARIZER_DISTANCE, RETARDER_DISTANCE = 30.0, 100.0, 90.0


def _direction(polar_deg, azimuth_deg):
    t, p = math.radians(polar_deg), math.radians(azimuth_deg)
    return np.array([math.sin(t) * math.cos(p), math.sin(t) * math.sin(p), math.cos(t)])


@dataclass(frozen=True)
class Configuration:
    """One picture: view and light directions ((polar, azimuth) deg from +z), polarizer state."""

    view: tuple
    light: tuple
    polarizer: float | None = None     # transmission axis (deg), None: unpolarized light
    retarder: float | None = None      # quarter-wave fast axis (deg) after the polarizer, None: none

    @property
    def facet_angle(self) -> float:
        """beta (deg): half the angle between the directions to the camera and to the light."""
        c = float(np.clip(_direction(*self.view) @ _direction(*self.light), -1.0, 1.0))
        return math.degrees(math.acos(c)) / 2.0

    @property
    def half_vector_tilt(self) -> float:
        """Angle (deg) of the half-vector from the sample normal (0 for a mirror pair)."""
        h = _direction(*self.view) + _direction(*self.light)
        return math.degrees(math.acos(float(np.clip(h[2] / np.linalg.norm(h), -1.0, 1.0))))

    @property
    def elements(self) -> tuple:
        """The Mueller elements a Stokes camera measures in this configuration (module table)."""
        return self._elements()

    def elements_for(self, camera: str = "stokes") -> tuple:
        """The Mueller elements ``camera`` ("stokes" or "linear") measures: a linear camera misses the
        output's S3, i.e. the row M3x."""
        return tuple(e for e in self._elements() if camera == "stokes" or e[1] != "3")

    def _elements(self) -> tuple:
        if self.polarizer is None:
            return ("M00", "M10", "M20", "M30")
        if self.retarder is not None:
            return ("M00", "M10", "M23", "M33")
        a = self.polarizer % 180.0
        if a in (0.0, 90.0):
            return ("M00", "M01", "M10", "M11")
        return ("M00", "M10", "M22", "M32") if a == 45.0 or a == 135.0 else ("M00", "M01", "M10", "M11",
                                                                               "M22", "M32")

    def label(self) -> str:
        pol = "unpol." if self.polarizer is None else f"pol {self.polarizer:g}" + (
            f" + QWP {self.retarder:g}" if self.retarder is not None else "")
        return f"view {self.view[0]:g}/{self.view[1]:g}, light {self.light[0]:g}/{self.light[1]:g}, {pol}"


@dataclass
class Acquisition:
    """A designed set of :class:`Configuration` (one picture each)."""

    configurations: list = field(default_factory=list)
    preset: str = ""
    camera: str = "stokes"             # what the camera measures (:data:`CAMERAS`)

    @property
    def measured(self) -> tuple:
        """The Stokes component names the camera measures."""
        return tuple(f"S{i}" for i in CAMERA_COMPONENTS[self.camera])

    def facet_angles(self) -> np.ndarray:
        return np.array([c.facet_angle for c in self.configurations])

    def polarized(self) -> int:
        return sum(c.polarizer is not None for c in self.configurations)

    def table(self) -> str:
        """A plain-text table: configuration, facet angle, half-vector tilt, elements."""
        rows = [f"{'#':>2}  {'configuration':48s} {'beta':>6} {'tilt':>6}  elements"]
        for i, c in enumerate(self.configurations):
            rows.append(f"{i:2d}  {c.label():48s} {c.facet_angle:6.1f} {c.half_vector_tilt:6.1f}  "
                        + " ".join(c.elements_for(self.camera)))
        return "\n".join(rows)


def design_acquisition(preset: str = "dielectric", *, facet_angles=MIRROR_FACET_ANGLES,
                       off_specular=OFF_SPECULAR, polarizer_angles=None, retarder=None,
                       camera: str = "stokes") -> Acquisition:
    """The observation set for a material sample (see the module docstring for what each
    configuration constrains).

    ``preset``: ``"dielectric"`` (unpolarized light) or ``"metal"`` (mirror pairs behind a linear
    polarizer at 45 deg, so that the retardance elements M22, M32 enter, plus circular light at
    :data:`METAL_RETARDER_FACET_ANGLES`).  ``facet_angles``: the mirror pairs' beta (deg, in (0, 89));
    ``off_specular``: (view polar, light polar) pairs for the roughness; ``polarizer_angles``: the
    polarizer states of the mirror pairs (default: none for "dielectric", (45,) for "metal"; None in
    the tuple means unpolarized); ``retarder``: circular states -- a polarizer at 0 deg followed by a
    quarter-wave retarder at 45 deg (M23, M33) -- at these facet angles (deg; ``True``: at every
    mirror pair, ``False`` or ``()``: none; default: none for "dielectric",
    :data:`METAL_RETARDER_FACET_ANGLES` for "metal", and at every mirror pair for "metal" with a
    linear camera).  ``camera``: what the camera measures, ``"stokes"`` (S0..S3) or ``"linear"``
    (S0..S2).  A linear camera does not see the output's S3, so the 45 deg state gives C (M22) but
    not S (M32); circular light brings S back through S2 (M23): the linear metal preset puts circular
    light (polarizer 0 deg + quarter-wave retarder at 45 deg) on every mirror pair, besides the 45 deg
    polarizer.
    """
    if preset not in PRESETS:
        raise UsageError(f"preset must be one of {PRESETS}, got {shorten(preset)}")
    if camera not in CAMERAS:
        raise UsageError(f"camera must be one of {CAMERAS}, got {shorten(camera)}")
    betas = [float(b) for b in facet_angles]
    if not betas or not all(0.0 < b < 89.0 for b in betas):
        raise UsageError(f"facet_angles must be angles in (0, 89) deg, got {shorten(tuple(facet_angles))}")
    if polarizer_angles is None:
        polarizer_angles = (None,) if preset == "dielectric" else (45.0,)
    for a in polarizer_angles:
        if a is not None and not math.isfinite(float(a)):
            raise UsageError(f"polarizer_angles must be finite angles in deg or None, "
                             f"got {shorten(polarizer_angles)}")
    if retarder is None:
        retarder = () if preset == "dielectric" else (True if camera == "linear" else METAL_RETARDER_FACET_ANGLES)
    circular = list(betas) if retarder is True else [] if retarder is False else [float(b) for b in retarder]
    if not all(0.0 < b < 89.0 for b in circular):
        raise UsageError(f"retarder facet angles must be angles in (0, 89) deg, got {shorten(tuple(circular))}")
    configs = []
    for b in betas:
        for a in polarizer_angles:
            configs.append(Configuration((b, 0.0), (b, 180.0), None if a is None else float(a)))
    for b in circular:
        configs.append(Configuration((b, 0.0), (b, 180.0), 0.0, 45.0))
    for tv, tl in off_specular:
        if not (0.0 <= tv < 89.0 and 0.0 <= tl < 89.0):
            raise UsageError(f"off_specular polar angles must be in [0, 89) deg, got {(tv, tl)}")
        configs.append(Configuration((float(tv), 0.0), (float(tl), 180.0)))
    return Acquisition(configs, preset, camera)


def fixed_rig_acquisition(preset: str = "dielectric", *, facet_angle: float = 50.0,
                          tilts=(-16.0, -8.0, 0.0, 8.0, 16.0), polarizer_angles=None) -> Acquisition:
    """A camera and a light on a fixed rig (the angle between them 2 x ``facet_angle``), the sample
    tilted so that the half-vector leans ``tilts`` deg from its normal in the plane of incidence:
    every picture has the *same* facet angle.  The roughness is seen through the tilts; the index
    only through what one facet angle says.  With an unknown per-texel scale the intensity then
    says nothing about the index (the scale absorbs the Fresnel factor F(beta; eta), the same in
    every picture), while the Stokes ratios B/A (and, behind the 45 deg polarizer of ``"metal"``,
    C/A and S/A) still determine it: the validation's unknown-scale runs use this design."""
    if preset not in PRESETS:
        raise UsageError(f"preset must be one of {PRESETS}, got {shorten(preset)}")
    b = float(facet_angle)
    if not 0.0 < b < 80.0:
        raise UsageError(f"facet_angle must be in (0, 80) deg, got {shorten(facet_angle)}")
    if polarizer_angles is None:
        polarizer_angles = (None,) if preset == "dielectric" else (45.0,)
    configs = []
    for tau in tilts:
        tv, tl = float(tau) + b, float(tau) - b           # signed polar angles in the x-z plane
        if not (abs(tv) < 89.0 and abs(tl) < 89.0):
            raise UsageError(f"tilt {shorten(tau)} deg with facet angle {b} deg puts the camera or the light below "
                             f"the horizon")
        view = (abs(tv), 0.0 if tv >= 0 else 180.0)
        light = (abs(tl), 0.0 if tl >= 0 else 180.0)
        for a in polarizer_angles:
            configs.append(Configuration(view, light, None if a is None else float(a)))
    return Acquisition(configs, f"{preset} (fixed rig, beta {b:g} deg)")


def _input_stokes(config: Configuration) -> np.ndarray:
    """The light's Stokes vector after the configuration's polarizer and retarder (unit S0 before
    them; an ideal polarizer passes half of unpolarized light; the retarder is a quarter-wave plate,
    :func:`~hyde_bsdf.model.polarimetry.retarder_mueller`)."""
    if config.polarizer is None:
        return np.array([1.0, 0.0, 0.0, 0.0])
    a = math.radians(2.0 * config.polarizer)
    s = np.array([1.0, math.cos(a), math.sin(a), 0.0]) / 2.0
    if config.retarder is not None:
        s = retarder_mueller(config.retarder, 90.0) @ s
    return s


def predicted_stderr(acquisition: Acquisition, values: dict, *, fit=("alpha", "eta", "k"), noise: float = 0.01,
                     pixels_per_texel: float = 16.0, diffuse: str = "paper", camera: str | None = None) -> dict:
    """Relative standard errors that ``acquisition`` would give a texel, from the Fisher information
    of the NumPy evaluator (:func:`hyde_bsdf.pbrdf`, an independent derivation of the plugin) -- in
    milliseconds, before rendering anything: the tool for designing an acquisition.

    ``values``: the texel's ``alpha`` (Beckmann), ``eta``, ``k`` and ``specular_reflectance`` (numbers
    or equal-shaped arrays: one prediction per entry); ``fit``: the parameters fitted (the others
    held at their values); ``noise``: the camera's noise standard deviation on each Stokes component,
    as a fraction of the texel's S0 in each picture (one number, or 4 for S0..S3: an ideal DoFP camera
    limited by read noise has sigma(S1) = sigma(S2) = sqrt(2) sigma(S0)); ``pixels_per_texel``: pixels covering a texel
    seen along the normal.  A picture with view polar angle theta_v sees the texel foreshortened,
    and only the pixels lying wholly inside it count (as in :mod:`hyde_bsdf.inverse.uncertainty`):
    (side - 1) (side cos theta_v - 1) of them, side = sqrt(pixels_per_texel).  Every configuration
    is taken as a mirror or off-specular pair in the plane of incidence (the presets').  ``camera``:
    "stokes" or "linear" (default: the acquisition's), the components that enter the information.  Returns
    name -> relative standard error (inf where the information is singular).  Agrees with the
    rendered information of :func:`~hyde_bsdf.inverse.uncertainty.information_blocks` to ~6 %
    (tests/test_inverse_capture.py)."""
    from hyde_bsdf.model.evaluator import pbrdf

    names = ("alpha", "eta", "k", "specular_reflectance")
    for n in fit:
        if n not in names:
            raise UsageError(f"fit names must be from {names}, got {shorten(n)}")
    camera = acquisition.camera if camera is None else camera
    if camera not in CAMERAS:
        raise UsageError(f"camera must be one of {CAMERAS}, got {shorten(camera)}")
    rows = list(CAMERA_COMPONENTS[camera])
    noise_c = np.broadcast_to(np.asarray(noise, np.float64), (4,)) if np.size(noise) in (1, 4) else None
    if noise_c is None or not (np.all(noise_c > 0) and pixels_per_texel > 0):
        raise UsageError(f"noise (a number or 4, S0..S3) and pixels_per_texel must be > 0, got "
                         f"{shorten(noise)}, {shorten(pixels_per_texel)}")
    if "alpha" not in values or "eta" not in values:
        raise UsageError(f"values must give alpha and eta, got {shorten(sorted(values))}")
    v = {n: np.asarray(values.get(n, {"k": 0.0, "specular_reflectance": 1.0}.get(n)), np.float64) for n in names}
    shape = np.broadcast_shapes(*(x.shape for x in v.values()))
    v = {n: np.broadcast_to(x, shape).ravel() for n, x in v.items()}
    side = math.sqrt(float(pixels_per_texel))

    def stokes(cfg, a, eta, k, scale):
        ti, tv = math.radians(cfg.light[0]), math.radians(cfg.view[0])
        F = pbrdf(ti, tv, math.pi, rms_slope=a / math.sqrt(2.0), n=eta, k=max(k, 0.0), diffuse=diffuse)
        return scale * (F @ _input_stokes(cfg)) * math.cos(ti)

    P, h = len(fit), 1e-4
    out = np.full((v["alpha"].size, P), np.inf)
    for t in range(v["alpha"].size):
        theta = {n: float(v[n][t]) for n in names}
        info = np.zeros((P, P))
        for cfg in acquisition.configurations:
            count = max(side - 1.0, 0.0) * max(side * math.cos(math.radians(cfg.view[0])) - 1.0, 0.0)
            S = stokes(cfg, *theta.values())
            J = []
            for n in fit:
                up, dn = dict(theta), dict(theta)
                up[n] *= math.exp(h)
                dn[n] *= math.exp(-h)
                J.append((stokes(cfg, *up.values()) - stokes(cfg, *dn.values())) / (2.0 * h))
            J = np.array(J)[:, rows]
            info += count * (J / (noise_c[rows] * S[0]) ** 2) @ J.T
        ev = np.linalg.eigvalsh(info)
        if ev.min() > 1e-12 * max(ev.max(), 1e-300):
            out[t] = np.sqrt(np.diag(np.linalg.inv(info)))
    return {n: out[:, i].reshape(shape) if shape else float(out[0, i]) for i, n in enumerate(fit)}


def _texture(value, filter_type: str = "nearest"):
    import mitsuba as mi

    if np.ndim(value) == 0:
        return float(value)
    arr = np.asarray(value, np.float32)
    return {"type": "bitmap", "bitmap": mi.Bitmap(arr[..., None]), "raw": True, "filter_type": filter_type}


def acquisition_scene_dict(config: Configuration, material: dict, *, bsdf: str = "hyde", res: int = 48,
                           spp: int = 4, irradiance: float = 2.0, extent: float = 1.05, shape: dict | None = None,
                           diffuse: str = "paper", shadowing: str | None = None,
                           filter_type: str = "nearest") -> dict:
    """The scene of one :class:`Configuration`: the sample (default a 2 x 2 ``rectangle``, id
    ``plane``, UV = (x + 1, y + 1) / 2; or ``shape``, any Mitsuba shape dict with UVs, whose
    ``bsdf`` is set here) with a BSDF whose parameters come from ``material`` (name -> float or an
    (rows, cols) map, rows along v, nearest-neighbour lookup: ``alpha``, ``eta``, ``k``,
    ``specular_reflectance``), a distant camera ``CAMERA_DISTANCE`` out along ``view`` whose
    field of view spans [-extent, extent] at the sample (``res`` x ``res`` pixels), a directional light of ``irradiance``
    from ``light``, and the polarizer / retarder sheets of the configuration.

    ``bsdf="roughconductor"`` (Beckmann, the same alpha, eta, k, specular_reflectance) for
    comparisons; ``shadowing`` is passed to ``hyde`` when given.  ``filter_type``: the maps' bitmap
    lookup, ``"nearest"`` (what the per-texel standard errors assume) or ``"bilinear"`` (Mitsuba's
    default; :func:`~hyde_bsdf.inverse.invert_maps` switches a fitted one to nearest, with a warning).
    """
    import mitsuba as mi

    if filter_type not in ("nearest", "bilinear"):
        raise UsageError(f"filter_type must be 'nearest' or 'bilinear', got {shorten(filter_type)}")
    T = mi.ScalarTransform4f
    mat = {name: _texture(v, filter_type) for name, v in material.items()}
    if bsdf == "hyde":
        bsdf_dict = {"type": "hyde", "diffuse": diffuse, **mat}
        if shadowing is not None:
            bsdf_dict["shadowing"] = shadowing
    elif bsdf == "roughconductor":
        bsdf_dict = {"type": "roughconductor", "distribution": "beckmann", **mat}
    else:
        raise UsageError(f"bsdf must be 'hyde' or 'roughconductor', got {shorten(bsdf)}")
    v, ldir = _direction(*config.view), _direction(*config.light)
    up = [0.0, 0.0, 1.0] if abs(v[2]) < 0.999 else [0.0, 1.0, 0.0]
    sheets = config.polarizer is not None
    fmt = {"pixel_format": "luminance"} if mi.is_monochromatic else {}
    sample = dict(shape) if shape is not None else {"type": "rectangle"}
    sample["bsdf"] = bsdf_dict
    scene = {
        "type": "scene",
        "integrator": {"type": "stokes", "integrator": {"type": "volpath" if sheets else "path", "max_depth": 2}},
        "sensor": {"type": "perspective", "fov": math.degrees(2.0 * math.atan(extent / CAMERA_DISTANCE)),
                   "to_world": T().look_at(origin=list(CAMERA_DISTANCE * v), target=[0, 0, 0], up=up),
                   "film": {"type": "hdrfilm", "width": int(res), "height": int(res), "rfilter": {"type": "box"},
                            **fmt},
                   "sampler": {"type": "independent", "sample_count": int(spp)}},
        "plane": sample,
        "light": {"type": "directional", "direction": list(-ldir),
                  "irradiance": {"type": "spectrum", "value": float(irradiance)}},
    }
    if sheets:
        lup = [0.0, 0.0, 1.0] if abs(ldir[2]) < 0.999 else [0.0, 1.0, 0.0]
        size = 1.6 * extent * math.sqrt(2.0)
        scene["polarizer"] = {"type": "rectangle", "bsdf": {"type": "polarizer", "theta": float(config.polarizer)},
                              "to_world": T().look_at(origin=list(POLARIZER_DISTANCE * ldir), target=[0, 0, 0], up=lup)
                              @ T().scale(size)}
        if config.retarder is not None:
            scene["retarder"] = {"type": "rectangle",
                                 "bsdf": {"type": "retarder", "theta": float(config.retarder), "delta": 90.0},
                                 "to_world": T().look_at(origin=list(RETARDER_DISTANCE * ldir), target=[0, 0, 0],
                                                         up=lup) @ T().scale(size)}
    return scene


def synthetic_observations(acquisition: Acquisition, truth: dict, start: dict, *, res: int = 48, spp: int = 4,
                           spp_ref: int = 256, noise=0.0, seed: int = 0, bsdf: str = "hyde", signal: float = 1000.0,
                           fit_filter_type: str | None = None, **scene_kwargs) -> list:
    """The observation set of ``acquisition`` for a synthetic sample: per configuration, a scene
    whose material holds ``start`` (the fit's start values; parameters absent there take
    ``truth``'s) and a reference rendered from ``truth`` at ``spp_ref`` samples, plus Gaussian
    noise of standard deviation ``noise`` x the median S0 of the lit pixels on each Stokes
    component (a camera's read noise; seeded by ``seed``).  Returns a list of
    :class:`~hyde_bsdf.inverse.observations.Observation`, each carrying the noise standard
    deviation it was given in ``.noise_std`` (0 when ``noise`` is 0).

    ``noise`` a :class:`~hyde_bsdf.model.polarimetry.CameraNoise` instead of a number: the
    reference goes through the acquisition's camera instead -- raw frames at ``signal`` DN (median lit
    S0) with that noise, a DoFP mosaic for a ``"linear"`` camera or six analyzer frames for a
    ``"stokes"`` one, and the least-squares Stokes step (:func:`~hyde_bsdf.model.polarimetry.simulate_capture`);
    the observation then carries the step's sigma maps and the measured components.

    ``fit_filter_type``: the bitmap filter of the fit's scenes when it differs from the reference's
    (``filter_type`` in ``scene_kwargs``, default nearest): a sample whose material changes from texel
    to texel (a nearest reference) fitted from a user's scene with Mitsuba's default bilinear maps.
    """
    import mitsuba as mi

    from hyde_bsdf.inverse.observations import Observation, render_stokes_np

    rng = np.random.default_rng(seed)
    observations = []
    for i, config in enumerate(acquisition.configurations):
        ref_scene = mi.load_dict(acquisition_scene_dict(config, truth, bsdf=bsdf, res=res, spp=spp, **scene_kwargs))
        ref = render_stokes_np(ref_scene, 0, spp_ref, seed=seed + i)
        del ref_scene
        sigma = 0.0
        sig_maps = None
        if not isinstance(noise, numbers.Real):                     # a camera's noise model
            est = simulate_capture(ref, noise, rng, camera=acquisition.camera, signal=signal)
            ref = np.array([est.stokes.get(c, np.zeros(ref.shape[1:])) for c in ("S0", "S1", "S2", "S3")])
            sig_maps = np.array([est.sigma.get(c, np.zeros(ref.shape[1:])) for c in ("S0", "S1", "S2", "S3")])
        elif noise > 0:
            lit = ref[0] > 0
            sigma = float(noise * np.median(ref[0][lit])) if lit.any() else 0.0
            ref = ref + rng.normal(0.0, sigma, ref.shape) * lit[None]
        # a parameter that is a map in the truth is a map (texture) in the fit's scene too
        material = {n: (np.full(np.shape(truth[n]), float(start[n])) if n in start and np.ndim(start[n]) == 0
                        and np.ndim(truth[n]) == 2 else start.get(n, truth[n])) for n in truth}
        fit_kwargs = scene_kwargs if fit_filter_type is None else {**scene_kwargs, "filter_type": fit_filter_type}
        scene = mi.load_dict(acquisition_scene_dict(config, material, bsdf=bsdf, res=res, spp=spp, **fit_kwargs))
        o = Observation(scene, ref, measured=acquisition.measured, sigma=sig_maps)
        o.noise_std = sigma
        observations.append(o)
    return observations


def example_material(case: str = "dielectric", n: int = 32) -> dict:
    """The validation's synthetic samples as parameter maps (n x n, rows along v):

    * ``"dielectric"``: eta a gradient 1.3 -> 2.2 along u plus a sharp-edged patch at 2.0, k = 0;
    * ``"metal"``: n from gold-like 0.45 to aluminium-like 1.2 along u, k from 2.4 to 6.7 along v,
      a sharp patch (n 0.7, k 4.0);

    both with Beckmann ``alpha`` 0.15 -> 0.4 along v (a ripple along u, a sharp patch at 0.5) and a
    ``specular_reflectance`` map 0.6-1.4 (the unknown scale of the validation's third run).
    """
    if case not in PRESETS:
        raise UsageError(f"case must be one of {PRESETS}, got {shorten(case)}")
    u = (np.arange(int(n)) + 0.5) / int(n)
    U, V = np.meshgrid(u, u)
    patch = (U >= 0.55) & (U < 0.85) & (V >= 0.2) & (V < 0.5)
    alpha = 0.15 + 0.25 * V + 0.03 * np.sin(2 * np.pi * U)
    alpha[(U >= 0.15) & (U < 0.4) & (V >= 0.6) & (V < 0.85)] = 0.5
    scale = 1.0 + 0.4 * np.sin(2 * np.pi * (U + 0.5 * V))
    if case == "dielectric":
        eta = 1.3 + 0.9 * U
        eta[patch] = 2.0
        return {"alpha": alpha, "eta": eta, "k": 0.0, "specular_reflectance": scale}
    nn = 0.45 + 0.75 * U
    kk = 2.4 + 4.3 * V
    nn[patch], kk[patch] = 0.7, 4.0
    return {"alpha": alpha, "eta": nn, "k": kk, "specular_reflectance": scale}
