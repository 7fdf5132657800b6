"""The Stokes-image loss of inverse rendering, its mask, and the smoothness regulariser of maps.

Loss (``components="stokes"``, the default)::

    L = <m (S0 - R0)^2> / <m R0^2>  +  <m sum_{c=1..3} (Sc - Rc)^2> / <m sum_{c=1..3} Rc^2>

with S, R the luminance (Y = 0.2126 R + 0.7152 G + 0.0722 B) of each Stokes
component of the rendering and the reference, <.> the image mean and m a mask of
the pixels whose footprint lies entirely on the object (its silhouette pixels
are partly covered and carry the largest sampling noise; they say nothing about
the material).  ``components="s0"`` keeps the first term only (an ordinary
intensity image).  The polarization terms share one normalization, so the loss
compares all of them in the same radiometric units.  With unpolarized light
sources one reflection gives S3 = 0 (Eq. 11: the facet Mueller matrix maps an
unpolarized Stokes vector to (M00, M01, 0, 0)); the S3 term then only has to
stay zero.

Camera data (``measured``, ``sigma``).  A camera measures some of the components: a linear
polarization camera S0, S1, S2 only.  ``measured`` names them; the others are not in the loss (their
reference values are ignored).  With per-pixel noise ``sigma`` (4, H, W) or (4,) -- standard
deviations of the reference's components, from :mod:`hyde_bsdf.model.polarimetry` or a noise model --
each term is weighted by its inverse variance (the maximum-likelihood weights) and the loss is::

    L = sum_{c measured} <m (Sc - Rc)^2 / sigma_c^2>  /  <m R0^2 / sigma_0^2>

(1 = a black rendering, as without ``sigma``); pixels with sigma = 0 or non-finite are masked out.
:attr:`StokesLoss.weights_np` gives the per-pixel, per-component weights either way (the uncertainty
uses them).
"""
from __future__ import annotations

import numpy as np

from hyde_bsdf.errors import UsageError, shorten
from hyde_bsdf.inverse._common import Y_WEIGHTS

__all__ = ["stokes_images", "channel_names", "interior_mask", "StokesLoss", "smoothness", "REFERENCE_RANGE",
           "check_reference_scale", "as_mask"]

#: accepted range of a reference's peak |S0| (radiance in the scene's units).  The loss squares
#: differences in float32 (largest 3.4e38): a peak of 1e10 leaves 18 orders of magnitude of headroom
#: for sums over the image; below 1e-10 the squares of the differences (1e-20 and less) fall into
#: float32's subnormal range and the gradients vanish.  Renders of real scenes lie far inside.
REFERENCE_RANGE = (1e-10, 1e10)


def check_reference_scale(ref, what: str = "the reference") -> float:
    """The peak |S0| of reference images ``ref`` (4, H, W); ValueError naming ``what`` when it is not
    finite or lies outside :data:`REFERENCE_RANGE` (such a reference cannot be matched by a
    rendering, and its squared differences overflow or underflow float32)."""
    ref = np.asarray(ref, dtype=np.float64)
    if not np.isfinite(ref).all():
        bad = int((~np.isfinite(ref)).any(axis=0).sum())
        raise UsageError(f"{what} has {bad} pixel(s) with NaN or infinite Stokes values; the loss needs "
                         f"finite references")
    peak = float(np.abs(ref[0]).max()) if ref.size else 0.0
    lo, hi = REFERENCE_RANGE
    if not (lo <= peak <= hi):
        raise UsageError(f"{what} has peak |S0| = {peak:.3g}, outside the accepted range [{lo:g}, {hi:g}] "
                         f"(radiance in the scene's units: a reference {'scaled up' if peak > hi else 'black or scaled down'}"
                         f" beyond what a rendering can match); rescale it or fix its units")
    return peak



def as_mask(mask, what: str = "mask") -> np.ndarray:
    """``mask`` as booleans (non-zero: use the pixel); UsageError for NaN or infinite values (NaN != 0
    would count as "use": an all-NaN mask would mean every pixel) and for a mask that uses no pixel."""
    m = np.asarray(mask)
    if m.dtype != bool:
        bad = ~np.isfinite(m.astype(np.float64))
        if bad.any():
            raise UsageError(f"{what} has NaN or infinite values in {int(bad.sum())} of {bad.size} pixels: a mask "
                             "is 0 (leave the pixel out) or non-zero (use it)")
        m = m != 0
    if m.size and not m.any():
        raise UsageError(f"{what} leaves out every pixel: nothing to fit")
    return m


def stokes_images(img, channel_names):
    """Luminance S0..S3 images (4 tensors of shape (H, W), differentiable) of a ``stokes`` render."""
    index = {n: i for i, n in enumerate(channel_names)}
    out = []
    for s in ("S0", "S1", "S2", "S3"):
        out.append(sum(w * img[:, :, index[f"{s}.{c}"]] for c, w in zip("RGB", Y_WEIGHTS)))
    return out


def channel_names(scene, sensor: int = 0) -> list:
    """The channel names of a sensor's film under the scene's integrator (R, G, B[, A] or Y, then S0.R, ...),
    known before any render (a ``dr.freeze`` step needs them before its first call)."""
    film = scene.sensors()[int(sensor)].film()
    base = ["Y"] if film.base_channels_count() == 1 else ["R", "G", "B", "A"][:film.base_channels_count()]
    return base + list(scene.integrator().aov_names())


def interior_mask(s0) -> np.ndarray:
    """Pixels lit and away from the silhouette: S0 > 0 in the pixel and its 4 neighbours."""
    lit = np.asarray(s0) > 0
    mask = lit.copy()
    for axis in (0, 1):
        for shift in (1, -1):
            rolled = np.roll(lit, shift, axis=axis)
            edge = [slice(None)] * 2
            edge[axis] = 0 if shift == 1 else -1
            rolled[tuple(edge)] = False          # np.roll wraps around: the border has no neighbour
            mask &= rolled
    return mask


STOKES = ("S0", "S1", "S2", "S3")


def _measured_indices(measured) -> tuple:
    names = tuple(measured)
    bad = [m for m in names if m not in STOKES]
    if bad or "S0" not in names:
        raise UsageError(f"measured must name S0 and any of S1, S2, S3; got {shorten(list(names))}")
    return tuple(i for i, n in enumerate(STOKES) if n in names)


def _sigma_maps(sigma, shape) -> np.ndarray:
    """sigma (4,) or (4, H, W) as (4, H, W) float64; ValueError naming the problem."""
    sig = np.asarray(sigma, np.float64)
    if sig.shape == (4,):
        sig = np.broadcast_to(sig[:, None, None], (4,) + tuple(shape))
    if sig.shape != (4,) + tuple(shape):
        raise UsageError(f"sigma must have shape (4,) or (4, {shape[0]}, {shape[1]}), got {sig.shape}")
    if (sig < 0).any():
        raise UsageError("sigma has negative values; it is a standard deviation (>= 0)")
    return sig


class StokesLoss:
    """The loss of the module docstring against reference luminance Stokes images ``ref`` (4, H, W).

    ``measured``: the components the camera measured (default all four); ``sigma``: their noise
    standard deviations (4,) or (4, H, W) (None: the unweighted loss)."""

    def __init__(self, ref, mask=None, components: str = "stokes", measured=STOKES, sigma=None):
        import mitsuba as mi

        if components not in ("stokes", "s0"):
            raise UsageError(f"components must be 'stokes' or 's0', got {shorten(components)}")
        ref = np.asarray(ref, dtype=np.float64)
        check_reference_scale(ref)
        mask = interior_mask(ref[0]) if mask is None else as_mask(mask)
        active = _measured_indices(measured) if components == "stokes" else (0,)
        if sigma is not None:
            sig = _sigma_maps(sigma, ref.shape[1:])
            ok = np.isfinite(sig) & (sig > 0)
            mask = mask & np.all(ok[list(active)], axis=0)
        if not mask.any():
            raise UsageError("the reference image has no lit interior pixel: nothing to fit")
        self.components, self.measured, self.active = components, tuple(STOKES[i] for i in active), active
        self.mask_np = mask
        m = mask.astype(np.float64)
        self.norm0 = float((m * ref[0] ** 2).mean())
        self.normp = float((m * (ref[list(active[1:])] ** 2).sum(0)).mean()) if len(active) > 1 else 0.0
        if self.normp <= 0 and components == "stokes" and len(active) > 1:
            raise UsageError("the reference has no polarization (S1 = S2 = S3 = 0): use components='s0'")
        w = np.zeros((4,) + ref.shape[1:])
        if sigma is None:
            w[0] = m / self.norm0
            for c in active[1:]:
                w[c] = m / self.normp
        else:
            inv_var = np.where(ok, 1.0 / np.where(ok, sig, 1.0) ** 2, 0.0)
            norm = float((m * inv_var[0] * ref[0] ** 2).mean())
            for c in active:
                w[c] = m * inv_var[c] / norm
        self.weights_np = w
        self.sigma_np = None if sigma is None else sig
        self.ref = [mi.TensorXf(r.astype(np.float32)) for r in ref]
        self.weights = [mi.TensorXf(x.astype(np.float32)) for x in w]
        self.ref_np = ref

    def __call__(self, S, tensors=None):
        """Differentiable loss of luminance Stokes images ``S`` (list of 4 tensors).

        ``tensors``: this loss's own (reference list, weight list) (:attr:`tensors`) passed in explicitly,
        as a ``dr.freeze`` function needs every array it reads among its inputs.
        """
        import drjit as dr

        ref, w = self.tensors if tensors is None else tensors
        loss = dr.mean(w[0] * dr.square(S[0] - ref[0]), axis=None)
        if len(self.active) > 1:
            pol = sum(w[c] * dr.square(S[c] - ref[c]) for c in self.active[1:])
            loss = loss + dr.mean(pol, axis=None)
        return loss

    @property
    def tensors(self):
        """(reference tensors S0..S3, per-component weight tensors) as Dr.Jit arrays."""
        return self.ref, self.weights

    def numpy(self, S) -> float:
        """The same loss in float64 from NumPy images (4, H, W) (finite differences)."""
        S = np.asarray(S, dtype=np.float64)
        return float(sum((self.weights_np[c] * (S[c] - self.ref_np[c]) ** 2).mean() for c in self.active))



def smoothness(x, kind: str = "tv", eps: float = 1e-3):
    """Mean over the horizontal and vertical neighbour pairs of a map ``x`` (TensorXf (H, W, 1)).

    ``kind="tv"``: sqrt(d^2 + eps^2) - eps (total variation, smoothed at |d| < eps so it is
    differentiable; keeps sharp edges: a step costs its height once).  ``kind="l2"``: d^2
    (squared gradient; smooths noise and rounds edges).  d is the difference of the map's values
    (for alpha: dimensionless), so the regulariser has the units of d (tv) or d^2 (l2).
    """
    import drjit as dr

    H, W = x.shape[0], x.shape[1]
    terms = []
    if W > 1:
        terms.append((x[:, 1:, :] - x[:, :-1, :], H * (W - 1)))
    if H > 1:
        terms.append((x[1:, :, :] - x[:-1, :, :], (H - 1) * W))
    if kind not in ("tv", "l2"):
        raise UsageError(f"regularizer must be 'tv' or 'l2', got {shorten(kind)}")
    total, n = 0.0, 0
    for d, count in terms:
        pen = dr.sqrt(dr.square(d) + eps * eps) - eps if kind == "tv" else dr.square(d)
        total = total + dr.sum(pen, axis=None)
        n += count
    return total / max(n, 1)
