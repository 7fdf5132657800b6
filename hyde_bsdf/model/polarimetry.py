"""From raw analyzer images to Stokes images: N frames behind analyzers at known angles (a rotating
analyzer, optionally behind a retarder) or a division-of-focal-plane (DoFP) mosaic, solved by least
squares through an analysis matrix, with the camera's noise propagated to a standard deviation per
Stokes component and pixel.  Pure NumPy.

Conventions (stated once; every function here uses them):

* **Stokes basis**: the one of Mitsuba's ``stokes`` integrator and of the package's Stokes EXRs --
  x = image right, y = image up, propagation towards the viewer; S1 > 0 is polarization along the
  image rows, S2 > 0 at +45 deg (from image-right towards image-up), S3 Mitsuba's circular sign.
* **Angles** (an analyzer's transmission axis, a retarder's fast axis) in degrees, counter-clockwise
  from the image's rightward horizontal towards image-up, as the viewer sees the picture.  A data
  sheet that counts angles clockwise in the y-down pixel frame describes the same analyzer with
  -theta (45 and 135 swap; 0 and 90 stay).
* **Frames** are raw: digital numbers (DN) with the black level in them, float or integer arrays
  (H, W) or (H, W, C) (C colour or spectral channels, treated independently).  The signal is
  ``frame - black_level``.
* **Analysis matrix** A (N, 4): frame k's signal is I_k = A_k . S.  An ideal analyzer at theta
  has A_k = t/2 (1, cos 2 theta, sin 2 theta, 0) (t its transmission, 1 by default); a retarder
  in front of it (fast axis phi, retardance delta, light passing the retarder first) makes the row
  a(theta) R(phi, delta) (:func:`retarder_mueller`), which reaches S3.  A calibrated matrix is given
  whole: (N, 4) for the camera, or (H, W, N, 4) per output pixel.

**Measured components**: S0, S1, S2, and S3 when A's S3 column is not zero -- analyzers alone
are linear-only (S3 is *not measured*, not zero); a retarder in front of some frames adds S3.  The estimate is
S = P I with P = pinv(A_m) (A_m: the measured columns) and its covariance P diag(var I) P^T;
the reported sigma is the square root of its diagonal.  A badly conditioned A_m amplifies the noise
by its condition number: above ``max_condition`` (default 100; the ideal 3 or 4 analyzers at equal
steps have sqrt(2)) the frames are refused.

**Camera noise** (:class:`CameraNoise`, the EMVA 1288 linear model): ``gain`` K in DN per electron,
``read_noise`` in electrons, ``full_well`` in electrons, ``black_level`` in DN; a signal of s DN has
variance K s + (K read_noise)^2.  The variance is taken from each frame's own measured signal.

**Demosaicking** a DoFP mosaic (``layout``: the analyzer angle of each pixel of the repeating 2 x 2
cell, row by row; :data:`SONY_LAYOUT` = ((90, 45), (135, 0)) is the common Sony polarization
sensor's, in the sensor's own clockwise count -- check it against your camera's data sheet and the
angle convention above):

* ``"superpixel"`` -- each 2 x 2 cell gives one Stokes pixel: (H/2, W/2), a quarter of the pixels,
  half the resolution along each axis; the four analyzers see points one raw pixel apart, so a sharp
  edge inside a cell shows as false polarization.  Pixels are independent: the right input for the
  inverse's standard errors.
* ``"bilinear"`` -- each analyzer's samples (every other row and column) are interpolated
  bilinearly onto the full raw grid: (H, W) Stokes pixels, but detail finer than 2 raw pixels is
  not resolved (it aliases), neighbouring pixels share raw samples (correlated noise, which the
  inverse's standard errors ignore), and sigma varies over the 2 x 2 pattern (an interpolated value
  averages 2 or 4 samples: variance halved or quartered, propagated per pixel).

Bad input raises :class:`~hyde_bsdf.errors.UsageError` with one line naming the frame and the
problem: frames of unequal size, fewer than 3 frames, non-finite, negative or saturated pixels
(``saturated="mask"`` masks saturated pixels out instead), a singular or badly conditioned
analysis matrix.
"""
from __future__ import annotations

import math
import warnings
from dataclasses import dataclass, field

import numpy as np

from hyde_bsdf.errors import UsageError

__all__ = ["CameraNoise", "StokesEstimate", "SONY_LAYOUT", "DEMOSAIC_METHODS", "MAX_CONDITION",
           "retarder_mueller", "analysis_matrix", "stokes_from_frames", "stokes_from_mosaic",
           "simulate_frames", "simulate_mosaic", "propagated_sigma", "stokes_sigma",
           "write_stokes_estimate", "chart_stokes", "simulate_capture", "FULL_STOKES_FRAMES"]

STOKES = ("S0", "S1", "S2", "S3")
#: the 2 x 2 analyzer cell of the common Sony polarization sensors (IMX250MZR and kin), degrees
SONY_LAYOUT = ((90.0, 45.0), (135.0, 0.0))
DEMOSAIC_METHODS = ("superpixel", "bilinear")
#: condition number of the analysis matrix above which frames are refused (noise amplification)
MAX_CONDITION = 100.0


@dataclass(frozen=True)
class CameraNoise:
    """The camera's linear noise model (EMVA 1288): DN = K (electrons) + black level, electrons
    Poisson, plus read noise.  ``gain`` K: DN per electron; ``read_noise``: electrons rms;
    ``full_well``: electrons (a raw value at or above ``saturation`` DN is saturated);
    ``black_level``: DN."""

    gain: float = 1.0
    read_noise: float = 0.0
    full_well: float = math.inf
    black_level: float = 0.0

    def __post_init__(self):
        for name in ("gain", "read_noise", "full_well", "black_level"):
            v = getattr(self, name)
            ok = v > 0 if name in ("gain", "full_well") else v >= 0
            if not (isinstance(v, (int, float)) and ok and (math.isfinite(v) or name == "full_well")):
                raise UsageError(f"CameraNoise.{name} must be a {'positive' if name in ('gain', 'full_well') else 'non-negative'}"
                                 f" finite number (full_well may be inf), got {v!r}")

    @property
    def saturation(self) -> float:
        """The raw value (DN) at which a pixel is full."""
        return self.black_level + self.gain * self.full_well

    def variance(self, signal) -> np.ndarray:
        """Variance (DN^2) of a raw value whose signal above the black level is ``signal`` DN."""
        return self.gain * np.maximum(np.asarray(signal, np.float64), 0.0) + (self.gain * self.read_noise) ** 2

    def simulate(self, signal, rng) -> np.ndarray:
        """Raw frames (DN, float64) of a noiseless ``signal`` (DN above black): Poisson electrons,
        Gaussian read noise, clipped at the full well and at 0 DN (the converter's floor: with a black
        level of a few read-noise widths, as real cameras set it, the floor is never reached)."""
        e = rng.poisson(np.maximum(np.asarray(signal, np.float64), 0.0) / self.gain).astype(np.float64)
        e = e + rng.normal(0.0, self.read_noise, e.shape) if self.read_noise > 0 else e
        return np.maximum(np.minimum(e, self.full_well) * self.gain + self.black_level, 0.0)


@dataclass
class StokesEstimate:
    """Stokes images estimated from analyzer frames.  ``stokes`` / ``sigma``: component name ->
    array (H, W) or (H, W, C) (only the measured components, :attr:`measured`); ``mask``: bool (H, W),
    pixels where every frame was usable; ``method``: how it was demosaicked (or "frames")."""

    stokes: dict
    sigma: dict
    measured: tuple
    mask: np.ndarray
    method: str = "frames"
    condition: float = float("nan")
    notes: list = field(default_factory=list)

    @property
    def shape(self) -> tuple:
        return self.stokes["S0"].shape[:2]

    def in_units(self, dn_per_unit: float) -> "StokesEstimate":
        """The estimate in scene radiance units: Stokes and sigma divided by the radiometric calibration
        ``dn_per_unit`` (DN per radiance unit at this exposure)."""
        k = float(dn_per_unit)
        if not (math.isfinite(k) and k > 0):
            raise UsageError(f"dn_per_unit must be a finite number > 0, got {dn_per_unit!r}")
        return StokesEstimate({c: v / k for c, v in self.stokes.items()}, {c: v / k for c, v in self.sigma.items()},
                              self.measured, self.mask, self.method, self.condition,
                              self.notes + [f"divided by {k:g} DN per radiance unit"])


def retarder_mueller(fast_axis: float, retardance: float = 90.0) -> np.ndarray:
    """Mueller matrix (4, 4) of a linear retarder, fast axis at ``fast_axis`` deg, retardance
    ``retardance`` deg (90: quarter-wave); the convention of the acquisition's light-side retarder."""
    c, s = math.cos(math.radians(2 * fast_axis)), math.sin(math.radians(2 * fast_axis))
    cd, sd = math.cos(math.radians(retardance)), math.sin(math.radians(retardance))
    return np.array([[1, 0, 0, 0],
                     [0, c * c + s * s * cd, c * s * (1 - cd), -s * sd],
                     [0, c * s * (1 - cd), s * s + c * c * cd, c * sd],
                     [0, s * sd, -c * sd, cd]])


def analysis_matrix(angles, retarder=None, transmission=1.0) -> np.ndarray:
    """A (N, 4) of ideal analyzers at ``angles`` (deg); ``retarder``: None, or (fast axis, retardance)
    in degrees -- one pair for every frame or one per frame (None entries: no retarder in that frame);
    ``transmission``: the analyzers' transmission (a number or one per frame)."""
    angles = np.atleast_1d(np.asarray(angles, np.float64))
    t = np.broadcast_to(np.asarray(transmission, np.float64), angles.shape)
    rows = 0.5 * t[:, None] * np.stack([np.ones_like(angles), np.cos(np.radians(2 * angles)),
                                        np.sin(np.radians(2 * angles)), np.zeros_like(angles)], axis=1)
    if retarder is None:
        return rows
    single = len(retarder) == 2 and all(isinstance(x, (int, float, np.floating)) for x in retarder)
    per = [retarder] * len(angles) if single else list(retarder)
    if len(per) != len(angles):
        raise UsageError(f"retarder: give one (fast axis, retardance) pair or one per frame ({len(angles)}), got {len(per)}")
    return np.array([r if p is None else r @ retarder_mueller(*p) for r, p in zip(rows, per)])


def _frame_label(k, names, angles) -> str:
    name = f"frame {k}" if names is None else f"frame {names[k]!s}"
    return name if angles is None else f"{name} (analyzer {angles[k]:g} deg)"


def _check_raw(frames, noise: CameraNoise, names, angles, saturated: str):
    """Frames as float64 (N, H, W, C) and the mask of usable pixels (H, W); one-line UsageErrors."""
    if len(frames) < 3:
        raise UsageError(f"need at least 3 analyzer frames to solve for S0, S1, S2; got {len(frames)}")
    arrs = [np.asarray(f) for f in frames]
    ref = arrs[0].shape
    for k, a in enumerate(arrs):
        if a.ndim not in (2, 3) or min(a.shape[:2]) < 1:
            raise UsageError(f"{_frame_label(k, names, angles)}: shape {a.shape}; a frame is (H, W) or (H, W, C)")
        if a.shape != ref:
            raise UsageError(f"{_frame_label(k, names, angles)} is {a.shape[1]}x{a.shape[0]}"
                             f"{'' if a.ndim == 2 else f'x{a.shape[2]}'} but {_frame_label(0, names, angles)} is "
                             f"{ref[1]}x{ref[0]}{'' if len(ref) == 2 else f'x{ref[2]}'}: frames must be equal in size")
    I = np.stack([a.astype(np.float64) if a.ndim == 3 else a.astype(np.float64)[..., None] for a in arrs])
    mask = np.ones(I.shape[1:3], bool)
    for k in range(len(arrs)):
        mask &= _check_raw_one(I[k], noise, _frame_label(k, names, angles), saturated)
    _check_light(I, noise, "the frames")
    return I, mask


def _check_light(I, noise, name):
    """UsageError when no raw value (of any frame: one analyzer may see none of a polarized light) is
    above the black level beyond the read noise (5 sigma and half a DN of rounding): no light reached the
    sensor, and every Stokes value would be 0 -- an empty answer, not a measurement."""
    if not (I - noise.black_level > 5.0 * noise.gain * noise.read_noise + 0.5).any():
        raise UsageError(f"{name}: no pixel is above the black level {noise.black_level:g} DN beyond the read noise "
                         f"(the brightest is {float(I.max()):g} DN): no light reached the sensor (a lens cap, a zero "
                         "exposure?)")


def _first_bad(bad):
    """(count, 'row r, column c') of the pixels where ``bad`` (H, W, C) holds, or None."""
    bad = np.asarray(bad).any(axis=-1)
    if not bad.any():
        return None
    r, c = np.argwhere(bad)[0]
    return int(bad.sum()), f"row {r}, column {c}"


def _measured_columns(A) -> tuple:
    """S0, S1, S2 always (a linear polarimeter must determine all three), S3 when A's S3 column is
    not zero (a retarder in front of some analyzer)."""
    norms = np.sqrt((np.asarray(A) ** 2).reshape(-1, 4).sum(axis=0))
    return (0, 1, 2, 3) if norms[3] > 1e-9 * norms.max() else (0, 1, 2)


def _pseudo_inverse(A, cols, max_condition: float, angles):
    """P = pinv(A[..., cols]) and the (largest) condition number; UsageError when singular or above
    ``max_condition``."""
    Am = np.asarray(A, np.float64)[..., list(cols)]
    sv = np.linalg.svd(Am, compute_uv=False)
    cond = np.where(sv[..., -1] > 0, sv[..., 0] / np.where(sv[..., -1] > 0, sv[..., -1], 1.0), np.inf)
    worst = float(np.max(cond))
    what = "the analysis matrix" if angles is None else f"the analysis matrix of the angles {[float(a) for a in angles]} deg"
    if not math.isfinite(worst) or worst > 1e12:
        raise UsageError(f"{what} is singular for {[STOKES[c] for c in cols]}: the frames do not determine them "
                         f"(analyzer angles must differ, modulo 180 deg, at least 3 distinct)")
    if worst > max_condition:
        raise UsageError(f"{what} is badly conditioned (condition number {worst:.3g} > {max_condition:g}): it "
                         f"amplifies the noise by that factor; spread the analyzer angles over 180 deg")
    return np.linalg.pinv(Am), worst


def propagated_sigma(P, variance) -> np.ndarray:
    """Per-component standard deviation of S = P I for independent frames of ``variance``:
    sqrt(sum_k P_ck^2 var_k).  P (M, N) or (H, W, M, N); variance (N, H, W, C) -> (M, H, W, C)."""
    if P.ndim == 2:
        return np.sqrt(np.einsum("mn,nhwc->mhwc", P ** 2, variance))
    return np.sqrt(np.einsum("hwmn,nhwc->mhwc", P ** 2, variance))


def _solve(I, var, A, cols, max_condition, angles):
    """S (M, H, W, C), sigma (M, H, W, C) and the condition number from signals I (N, H, W, C)."""
    A = np.asarray(A, np.float64)
    H, W = I.shape[1:3]
    if A.ndim == 4 and A.shape[:2] != (H, W):
        raise UsageError(f"the per-pixel analysis matrix is {A.shape[1]}x{A.shape[0]} but the Stokes image is {W}x{H}")
    P, cond = _pseudo_inverse(A, cols, max_condition, angles)
    S = np.einsum("mn,nhwc->mhwc", P, I) if P.ndim == 2 else np.einsum("hwmn,nhwc->mhwc", P, I)
    return S, propagated_sigma(P, var), cond


def _estimate(I, var, A, mask, max_condition, angles, method, squeeze):
    A = np.asarray(A, np.float64)
    if A.shape[-2] != I.shape[0] or A.shape[-1] != 4 or A.ndim not in (2, 4):
        raise UsageError(f"the analysis matrix must be (N, 4) or (H, W, N, 4) with N = {I.shape[0]} frames; "
                         f"got {A.shape}")
    if not np.any(mask):           # no silent all-zero estimate
        raise UsageError("no pixel is usable (each is saturated or below the black level in some frame, or "
                         "shares a superpixel cell with one): nothing to estimate")
    if not np.isfinite(A).all():
        raise UsageError("the analysis matrix has NaN or infinite entries; a calibrated matrix is finite")
    cols = _measured_columns(A)
    S, sig, cond = _solve(I, var, A, cols, max_condition, angles)
    S = np.where(mask[None, :, :, None], S, 0.0)
    sig = np.where(mask[None, :, :, None], sig, 0.0)
    out = (lambda a: a[..., 0]) if squeeze else (lambda a: a)
    names = tuple(STOKES[c] for c in cols)
    return StokesEstimate({n: out(S[i]) for i, n in enumerate(names)}, {n: out(sig[i]) for i, n in enumerate(names)},
                          names, mask, method, cond)


def stokes_from_frames(frames, angles=None, *, analysis=None, retarder=None, noise: CameraNoise = CameraNoise(),
                       saturated: str = "error", names=None, max_condition: float = MAX_CONDITION) -> StokesEstimate:
    """Stokes images from N >= 3 raw frames behind analyzers at ``angles`` (deg; with an optional
    ``retarder`` (fast axis, retardance) in front, see :func:`analysis_matrix`) or through a calibrated
    ``analysis`` matrix (N, 4) or (H, W, N, 4).  ``names``: labels of the frames in messages (e.g.
    their file names).  See the module docstring for the conventions, the noise and the checks."""
    if (angles is None) == (analysis is None):
        raise UsageError("give the analyzer angles or a calibrated analysis matrix (one of them)")
    if angles is not None and len(angles) != len(frames):
        raise UsageError(f"{len(frames)} frames but {len(angles)} analyzer angles: give one angle per frame")
    I, mask = _check_raw(frames, noise, names, angles, saturated)
    I = I - noise.black_level
    A = analysis_matrix(angles, retarder) if analysis is None else analysis
    return _estimate(I, noise.variance(I), A, mask, max_condition, angles, "frames", np.ndim(frames[0]) == 2)


def _layout(layout) -> np.ndarray:
    lay = np.asarray(layout, np.float64)
    if lay.shape != (2, 2) or not np.isfinite(lay).all():
        raise UsageError(f"layout must be 2 x 2 analyzer angles in degrees, row by row, e.g. {SONY_LAYOUT}; got {layout!r}")
    return lay


def _tent(x, k1):
    """Separable 3 x 3 convolution of (H, W, C) with the 1-D kernel k1 (zero padding)."""
    p = np.pad(x, ((1, 1), (1, 1), (0, 0)))
    y = k1[0] * p[:-2] + k1[1] * p[1:-1] + k1[2] * p[2:]
    return k1[0] * y[:, :-2] + k1[1] * y[:, 1:-1] + k1[2] * y[:, 2:]


#: the 2 x 2 cell positions in ``layout`` order
CELL = ((0, 0), (0, 1), (1, 0), (1, 1))


def _demosaic(I, var, mask, method):
    """The 4 analyzer images (4, h, w, C), their variances and the usable-pixel mask (h, w)."""
    if method == "superpixel":
        Ic = np.stack([I[r::2, c::2] for r, c in CELL])
        Vc = np.stack([var[r::2, c::2] for r, c in CELL])
        return Ic, Vc, mask.reshape(mask.shape[0] // 2, 2, mask.shape[1] // 2, 2).all(axis=(1, 3))
    # bilinear: normalised convolution of each position's samples with the tent kernel (1/2, 1, 1/2)^2;
    # the variance of a weighted mean sum w_i x_i / sum w_i is sum w_i^2 var_i / (sum w_i)^2
    k1 = np.array([0.5, 1.0, 0.5])
    Ic, Vc = [], []
    for r, c in CELL:
        have = np.zeros(I.shape[:2] + (1,))
        have[r::2, c::2] = 1.0
        norm = _tent(have, k1)
        Ic.append(_tent(I * have, k1) / norm)
        Vc.append(_tent(var * have, k1 ** 2) / norm ** 2)
    m = _tent((~mask).astype(np.float64)[..., None], np.ones(3))[..., 0] == 0   # no saturated sample used
    return np.stack(Ic), np.stack(Vc), m


def stokes_from_mosaic(raw, layout=SONY_LAYOUT, *, method: str = "superpixel", analysis=None,
                       noise: CameraNoise = CameraNoise(), saturated: str = "error", name: str = "raw",
                       max_condition: float = MAX_CONDITION) -> StokesEstimate:
    """Stokes images from one DoFP mosaic ``raw`` (H, W) or (H, W, C) (H, W even) whose repeating 2 x 2
    cell has the analyzer angles ``layout`` (deg, row by row).  ``method``: "superpixel" ((H/2, W/2)
    output) or "bilinear" ((H, W) output) -- see the module docstring for what each costs.
    ``analysis``: a calibrated matrix for the 4 cell positions in ``layout`` order (4, 4), or per output
    pixel (h, w, 4, 4); default the ideal analyzers."""
    if method not in DEMOSAIC_METHODS:
        raise UsageError(f"method must be one of {DEMOSAIC_METHODS}, got {method!r}")
    lay = _layout(layout)
    arr = np.asarray(raw)
    if arr.ndim not in (2, 3) or arr.shape[0] < 2 or arr.shape[1] < 2 or arr.shape[0] % 2 or arr.shape[1] % 2:
        raise UsageError(f"{name}: a DoFP mosaic is (H, W) or (H, W, C) with H, W even and >= 2, got {arr.shape}")
    angles = lay.ravel()
    I = arr.astype(np.float64)
    I = I[..., None] if I.ndim == 2 else I
    mask = _check_raw_one(I, noise, name, saturated)
    _check_light(I, noise, name)
    I = I - noise.black_level
    Ic, Vc, m = _demosaic(I, noise.variance(I), mask, method)
    A = analysis_matrix(angles) if analysis is None else analysis
    return _estimate(Ic, Vc, A, m, max_condition, angles, method, arr.ndim == 2)


def _check_raw_one(I, noise, name, saturated):
    """The usable-pixel mask (H, W) of one raw frame or mosaic ``I`` (H, W, C) named ``name``; UsageError
    on non-finite or negative pixels, and on saturated ones unless ``saturated="mask"``."""
    if saturated not in ("error", "mask"):
        raise UsageError(f"saturated must be 'error' or 'mask', got {saturated!r}")
    for bad, what in ((~np.isfinite(I), "are NaN or infinite"), (I < 0, "are negative (raw frames are >= 0 DN)")):
        where = _first_bad(bad)
        if where:
            raise UsageError(f"{name}: {where[0]} pixel(s) {what} (first at {where[1]})")
    full = I >= noise.saturation
    where = _first_bad(full)
    if where and saturated == "error":
        raise UsageError(f"{name}: {where[0]} pixel(s) at or above the saturation level {noise.saturation:g} DN "
                         f"(first at {where[1]}); lower the exposure or pass saturated='mask' to leave them out")
    # calibrated: darker than the black level beyond the read noise (5 sigma: no false alarm in 10^6 pixels,
    # and half a DN of rounding) is no light -- a wrong black level, or a defect: left out; every pixel so, refused
    dark = I - noise.black_level < -(5.0 * noise.gain * noise.read_noise + 0.5)
    where = _first_bad(dark)
    if where:
        n = dark.shape[0] * dark.shape[1]
        if where[0] == n:
            raise UsageError(f"{name}: every pixel is below the black level {noise.black_level:g} DN beyond the read "
                             f"noise (the brightest is {float(I.max()):g} DN): the black level is wrong for this frame")
        warnings.warn(f"{name}: {100 * where[0] / n:.3g} % of the pixels ({where[0]} of {n}) are below the black "
                      f"level {noise.black_level:g} DN beyond the read noise (first at {where[1]}): left out (mask 0)",
                      UserWarning, stacklevel=4)
    return ~(full | dark).any(axis=-1)


def simulate_frames(stokes, A, noise: CameraNoise, rng) -> np.ndarray:
    """Raw frames (N, H, W[, C]) of a Stokes image ``stokes`` (4, H, W[, C]) in DN above black seen
    through the analysis matrix ``A`` (N, 4), with the camera's noise (``rng``: a NumPy Generator)."""
    S = np.asarray(stokes, np.float64)
    return noise.simulate(np.einsum("nm,m...->n...", np.asarray(A, np.float64), S), rng)


def simulate_mosaic(stokes, noise: CameraNoise, rng, layout=SONY_LAYOUT) -> np.ndarray:
    """A raw DoFP mosaic (2h, 2w[, C]) of a Stokes image (4, h, w[, C]) (one value per super-pixel, the
    same for its 4 raw pixels; DN above black), each raw pixel behind its ``layout`` analyzer."""
    S = np.asarray(stokes, np.float64)
    A = analysis_matrix(_layout(layout).ravel())
    frames = np.einsum("nm,m...->n...", A, S)               # (4, h, w[, C])
    h, w = S.shape[1:3]
    raw = np.zeros((2 * h, 2 * w) + S.shape[3:])
    for i, (r, c) in enumerate(CELL):
        raw[r::2, c::2] = frames[i]
    return noise.simulate(raw, rng)


def stokes_sigma(stokes, noise: CameraNoise, analysis=None) -> np.ndarray:
    """The sigma (M, ...) that a camera with ``noise`` and the analysis matrix ``analysis`` (default: ideal
    analyzers at 0/45/90/135 deg, a DoFP super-pixel) gives Stokes images ``stokes`` (M, ...) of its
    measured components (S0..S2, or S0..S3 when ``analysis`` reaches S3), in DN above black: the
    frames' variance from the noise model at the signal the Stokes vector predicts, propagated."""
    S = np.asarray(stokes, np.float64)
    A = analysis_matrix([0.0, 45.0, 90.0, 135.0]) if analysis is None else np.asarray(analysis, np.float64)
    cols = _measured_columns(A)
    if S.shape[0] != len(cols):
        raise UsageError(f"stokes has {S.shape[0]} components but the analysis matrix measures {len(cols)}")
    P, _ = _pseudo_inverse(A, cols, math.inf, None)
    var = noise.variance(np.einsum("nm,m...->n...", A[:, list(cols)], S))
    return np.sqrt(np.einsum("mn,n...->m...", P ** 2, var))


def _colours(est: StokesEstimate) -> tuple:
    C = est.stokes["S0"].shape[2] if est.stokes["S0"].ndim == 3 else 0
    return () if C == 0 else (("R", "G", "B") if C == 3 else tuple(f"C{i}" for i in range(C)))


def write_stokes_estimate(est: StokesEstimate, path, metadata=None):
    """Write a :class:`StokesEstimate` as a camera Stokes EXR, atomically: ``S0, S1, S2[, S3]`` -- with
    ``.R/.G/.B`` or ``.C0 ...`` for several channels -- their ``_sigma`` layers and the ``mask``; what
    ``invert --maps`` reads (:func:`hyde_bsdf.io.stokes_exr.write_camera_stokes`).  Returns the path."""
    from hyde_bsdf.io.stokes_exr import write_camera_stokes

    meta = {"measured": ",".join(est.measured), "demosaic": est.method, "condition": f"{est.condition:.4g}",
            **(metadata or {})}
    return write_camera_stokes(path, est.stokes, sigma=est.sigma, mask=est.mask, colours=_colours(est), metadata=meta)


def chart_stokes(est: StokesEstimate) -> dict:
    """The estimate as the (H, W, 3) Stokes dict the polarization charts take (a mono or multi-channel
    image as grey; S3 zero when not measured): for intensity, DoLP and AoLP pictures."""
    out = {}
    for c in STOKES:
        a = np.asarray(est.stokes[c], np.float64) if c in est.stokes else np.zeros(est.stokes["S0"].shape)
        a = a[..., None] if a.ndim == 2 else a
        out[c] = a if a.shape[2] == 3 else np.repeat(a.mean(axis=2, keepdims=True), 3, axis=2)
    return out


#: the full-Stokes camera of :func:`simulate_capture`: analyzers at 0/45/90/135 deg, then 45 and 135 deg
#: behind a quarter-wave retarder with its fast axis at 0 deg (rows 1/2 (1, 0, 0, +-1): S3)
FULL_STOKES_FRAMES = ((0.0, None), (45.0, None), (90.0, None), (135.0, None), (45.0, (0.0, 90.0)), (135.0, (0.0, 90.0)))


def simulate_capture(stokes, noise: CameraNoise, rng, *, camera: str = "linear", signal: float = 1000.0,
                     layout=SONY_LAYOUT) -> StokesEstimate:
    """A camera's Stokes estimate of a noiseless Stokes image ``stokes`` (4, H, W) in any radiance
    units: scaled so that the median S0 of the lit pixels is ``signal`` DN, captured with ``noise``,
    estimated, and scaled back (stokes and sigma in the input's units).  ``camera="linear"``: a DoFP
    mosaic (``layout``; each Stokes pixel one super-pixel, so no edge artefacts), demosaicked by
    super-pixel; ``"stokes"``: the six frames of :data:`FULL_STOKES_FRAMES`."""
    S = np.asarray(stokes, np.float64)
    lit = S[0] > 0
    scale = float(signal) / float(np.median(S[0][lit])) if lit.any() else 1.0
    if camera == "linear":
        raw = simulate_mosaic(S * scale, noise, rng, layout)
        est = stokes_from_mosaic(raw, layout, noise=noise, saturated="mask")
    elif camera == "stokes":
        angles = [a for a, _ in FULL_STOKES_FRAMES]
        A = analysis_matrix(angles, retarder=[r for _, r in FULL_STOKES_FRAMES])
        est = stokes_from_frames(list(simulate_frames(S * scale, A, noise, rng)), analysis=A, noise=noise,
                                 saturated="mask")
    else:
        raise UsageError(f"camera must be 'linear' or 'stokes', got {camera!r}")
    return est.in_units(scale)
