"""Texture-valued (SVBRDF) inverse rendering: per-texel roughness, index and scale maps from several
Stokes images (:func:`invert_maps`), with per-texel standard errors.

:func:`invert_maps` runs four steps, each its own function: the observation set-up
(:meth:`MapProblem.build`), the loss (:func:`map_loss`) and its gradient (:func:`map_step`), the
update (:class:`~hyde_bsdf.inverse.adam.LogAdam`), and the uncertainty (:func:`map_uncertainty`,
:mod:`hyde_bsdf.inverse.uncertainty`).
"""
from __future__ import annotations

import math
import time
import warnings
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from hyde_bsdf.errors import UsageError
from hyde_bsdf.inverse._common import (_first_line, freeze_step, record_iteration, seconds_per_iteration,
                                      write_history)
from hyde_bsdf.inverse.loss import StokesLoss, smoothness
from hyde_bsdf.inverse.observations import (MAP_PARAMETERS, _obs_mask, film_channels, map_keys, render_stokes,
                                            texel_coverage)
from hyde_bsdf.inverse.adam import LogAdam
from hyde_bsdf.options import Options
from hyde_bsdf.progress import as_callback
from hyde_bsdf.inverse.uncertainty import (CONVERGENCE_THRESHOLD, STDERR_THRESHOLD, BilinearFilterWarning,
                                           NotConvergedWarning, UnidentifiedParameterWarning, Uncertainty,
                                           accumulate_blocks, at_bounds, convergence_test, convergence_warnings,
                                           gauss_newton_step, identification_warnings, misfit_pvalues, pixel_records,
                                           standard_errors, texel_convergence, texel_misfit)

__all__ = ["MapOptions", "MapInversionResult", "MapProblem", "filters_bilinearly", "map_loss", "map_step", "map_uncertainty",
           "invert_maps"]


@dataclass
class MapInversionResult:
    """Outcome of :func:`invert_maps`: final maps/values (NumPy), per-iteration history, texel mask,
    and the per-texel standard errors (absolute and relative, NaN where unseen) with the warnings."""

    fitted: tuple
    final: dict                      # name -> ndarray (rows, cols) for maps, float for constants
    start: dict
    components: str
    seen: np.ndarray | None = None   # bool (rows, cols): texels some observation sees
    truth: dict | None = None
    history: list = field(default_factory=list)  # iteration, loss, data_loss, regularizer, seconds, [errors]
    seconds_per_iteration: float = float("nan")
    first_iteration_seconds: float = float("nan")
    stderr: dict = field(default_factory=dict)      # name -> (rows, cols) standard error of the final map
    rel_stderr: dict = field(default_factory=dict)  # name -> (rows, cols) stderr / value
    warnings: list = field(default_factory=list)    # messages: undetermined, unconverged, bilinear (each once)
    converged: dict = field(default_factory=dict)   # name -> (rows, cols) bool: False where the stderr is NaN
    uncertainty: Uncertainty | None = None
    adam_final: dict = field(default_factory=dict)  # the averaged Adam iterate before the polish
    tiles: list = field(default_factory=list)       # invert_maps_tiled: per tile bounds, pixels, s/it, peak RSS
    wall_seconds: float = float("nan")              # invert_maps_tiled: the whole run, planning included
    memory_estimate: int = 0                        # invert_maps_tiled: the estimate checked before the work (B)
    messages: list = field(default_factory=list)    # (category, message) of each warning

    def write_history(self, path) -> Path:
        """CSV: one row per iteration (loss terms, seconds, the maps' errors against the truth)."""
        errors = [k for k in self.history[0] if k.endswith("_error")] if self.history else []
        return write_history(path, self.history, ["iteration", "loss", "data_loss", "regularizer", "seconds", *errors])

    def texel_errors(self, name: str = "alpha") -> np.ndarray:
        """|final / truth - 1| over the seen texels of map ``name`` (1-D array)."""
        if not self.truth or name not in self.truth:
            raise UsageError(f"no truth for {name!r}")
        rel = np.abs(np.asarray(self.final[name]) / np.asarray(self.truth[name]) - 1.0)
        return rel[self.seen] if self.seen is not None and rel.shape == self.seen.shape else rel.ravel()

    def valid(self, name: str) -> np.ndarray:
        """(rows, cols) bool: texels seen, with a valid (finite) standard error -- the texels whose
        values are measurements.  Without the uncertainty step: the seen texels."""
        seen = np.ones(np.shape(self.final[name]), bool) if self.seen is None else np.asarray(self.seen, bool)
        if name in self.rel_stderr:
            seen = seen & np.isfinite(self.rel_stderr[name])
        return seen

    def measured(self, name: str) -> np.ndarray:
        """The fitted map with NaN where :meth:`valid` is False (unseen texels keep their start value in
        ``final``; this is what to report)."""
        return np.where(self.valid(name), np.asarray(self.final[name], np.float64), np.nan)

    def pulls(self, name: str) -> np.ndarray:
        """(final - truth) / stderr over the seen texels (1-D): standard normal when the errors are right."""
        if not self.truth or name not in self.truth or name not in self.stderr:
            raise UsageError(f"no truth or standard error for {name!r}")
        z = (np.asarray(self.final[name]) - np.asarray(self.truth[name])) / self.stderr[name]
        return z[self.seen] if self.seen is not None else z.ravel()


def _check_seen(seen):
    """``seen``, refused (before the work) when no texel is seen: all-NaN maps are no answer."""
    if seen is not None and not np.any(seen):
        raise UsageError(f"no picture sees the sample: texels seen 0 of {np.size(seen)} (check where the cameras "
                         "look, the `cameras` and `lights` files, and the `references`' masks)")
    return seen


@dataclass
class MapProblem:
    """Step 1, the observation set-up: the checked observations, their losses and weights, the
    scenes (each once) with their traverse keys, the texture shapes, the seen texels."""

    observations: list
    losses: list
    weights: list                     # o.weight / sum of weights
    scenes: list
    all_params: list
    keys: list                        # per scene: name -> traverse key
    names: tuple                      # fitted, then held fixed
    fit: tuple
    shapes: dict                      # name -> texture shape (rows, cols, 1) or None (a constant)
    scene_of: list                    # observation -> index into scenes
    channels: list                    # observation -> film channel names
    seen: np.ndarray | None
    prefix: str | None
    components: str
    bilinear: tuple = ()              # fitted maps whose bitmap filters bilinearly (in any scene)
    nearest: tuple = ()               # fitted maps switched from bilinear to nearest by build()

    @property
    def map_shape(self):
        return next((self.shapes[n][:2] for n in self.fit if self.shapes[n] is not None), None)

    @classmethod
    def build(cls, observations, start: dict, fit, *, components: str = "stokes", prefix: str | None = None,
              seen=None) -> "MapProblem":
        """Check the inputs (one-line ValueErrors naming the parameter) and set the start values
        into every scene."""
        import mitsuba as mi

        observations = list(observations)
        if not observations:
            raise UsageError("observations must hold at least one Observation")
        fit = tuple(fit)
        if not fit:
            raise UsageError(f"fit must name at least one of {tuple(MAP_PARAMETERS)}")
        for name in fit:
            if name not in MAP_PARAMETERS:
                raise UsageError(f"fit: unknown parameter {name!r}; use {', '.join(MAP_PARAMETERS)}")
            if name not in start:
                raise UsageError(f"start must give a value for every fitted parameter; missing {name!r}")
        for o in observations:
            ref = np.asarray(o.reference)
            if ref.ndim != 3 or ref.shape[0] != 4:
                raise UsageError(f"reference must have shape (4, H, W), got {ref.shape}")
            W, H = o.scene.sensors()[int(o.sensor)].film().crop_size()
            if ref.shape[1:] != (H, W):
                raise UsageError(f"reference is {ref.shape[2]}x{ref.shape[1]} pixels but sensor {o.sensor}'s "
                                 f"film is {W}x{H}")
            if not np.isfinite(ref).all():
                raise UsageError("reference contains NaN or infinite pixels")
        losses = [StokesLoss(o.reference, mask=_obs_mask(o), components=components, measured=o.measured,
                             sigma=o.sigma) for o in observations]
        wsum = float(sum(o.weight for o in observations))
        if not wsum > 0:
            raise UsageError("the observations' weights must sum to > 0")
        scenes = []
        for o in observations:
            if all(o.scene is not s for s in scenes):
                scenes.append(o.scene)
        all_params = [mi.traverse(s) for s in scenes]
        names = tuple(dict.fromkeys(list(fit) + [n for n in start if n not in fit]))
        keys = [map_keys(p, names, prefix) for p in all_params]
        shapes = {}
        for name in names:
            cur = all_params[0][keys[0][name]]
            shapes[name] = tuple(cur.shape) if isinstance(cur, mi.TensorXf) else None
        problem = cls(observations, losses, [o.weight / wsum for o in observations], scenes, all_params, keys,
                      names, fit, shapes, [next(i for i, s in enumerate(scenes) if s is o.scene) for o in observations],
                      [film_channels(o.scene, o.sensor) for o in observations], None, prefix, components)
        if seen is None and problem.map_shape is not None:
            seen = sum(texel_coverage(o, problem.map_shape, prefix) for o in observations) > 0
        problem.seen = _check_seen(seen)
        problem.bilinear = problem._bilinear_maps()
        if problem.bilinear:
            problem._to_nearest()
        for name in names:
            try:
                value = problem.as_value(name, start[name])
            except ValueError:
                raise UsageError(f"start[{name!r}] must be a number or an array of the texture's shape "
                                 f"{shapes[name][:2]}") from None
            problem.write({name: value})
        return problem

    def _bilinear_maps(self) -> tuple:
        """The fitted maps whose bitmap filters bilinearly in some scene."""
        return tuple(n for n in self.fit if self.shapes[n] is not None and any(
            filters_bilinearly(p, k[n], self.shapes[n], MAP_PARAMETERS[n][1])
            for p, k in zip(self.all_params, self.keys)))

    def _to_nearest(self) -> None:
        """Switch the bilinear fitted bitmaps to ``filter_type`` nearest in every scene
        (:func:`~hyde_bsdf.render.texture_filter.bitmap_to_nearest`), traverse the scenes again, and
        set ``nearest`` (switched) and ``bilinear`` (left bilinear: a BSDF that cannot take the swap)."""
        import mitsuba as mi

        from hyde_bsdf.render.texture_filter import bitmap_to_nearest

        switched = set()
        for i, scene in enumerate(self.scenes):
            for name in self.bilinear:
                if bitmap_to_nearest(scene, self.all_params[i], self.keys[i][name]):
                    switched.add(name)
                    self.all_params[i] = mi.traverse(scene)
                    self.keys[i] = map_keys(self.all_params[i], self.names, self.prefix)
        self.bilinear = self._bilinear_maps()
        self.nearest = tuple(n for n in self.fit if n in switched and n not in self.bilinear)

    def as_value(self, name, v):
        """``v`` (a number or a (rows, cols) array) as the Dr.Jit value of parameter ``name``, clamped
        to its range (:data:`MAP_PARAMETERS`)."""
        import mitsuba as mi

        lo, hi = MAP_PARAMETERS[name][1]
        shape = self.shapes[name]
        if shape is None:
            return mi.Float(float(np.clip(float(np.mean(v)), lo, hi)))
        arr = np.broadcast_to(np.asarray(v, np.float64).reshape(shape[:2] + (1,))
                              if np.ndim(v) else np.asarray(v, np.float64), shape)
        return mi.TensorXf(np.clip(arr, lo, hi).astype(np.float32))

    def write(self, values: dict) -> None:
        """Set parameter values (Dr.Jit arrays) into every scene."""
        for p, k in zip(self.all_params, self.keys):
            for name, v in values.items():
                p[k[name]] = v
            p.update()


def filters_bilinearly(params, key: str, shape, bounds) -> bool:
    """True when the bitmap texture whose data is ``params[key]`` (shape (rows, cols, 1)) filters
    bilinearly (Mitsuba's default): a test pattern whose every texel differs from its four neighbours
    (four values by row and column parity, within 10 % of one base value: in range for any map size;
    a pattern growing with the texel index left alpha's range from ~25 000 texels on) is written and the
    texture is evaluated a quarter texel off the centre of a corner texel -- nearest returns one
    texel's value exactly, bilinear a blend.  The caller writes its own values afterwards."""
    import mitsuba as mi

    rows, cols = int(shape[0]), int(shape[1])
    node = params.properties[key][2]
    if rows * cols < 2 or not isinstance(node, mi.Texture):
        return False
    lo, hi = bounds
    base = min(max(0.3, lo * 2), hi / 2)
    r, c = np.meshgrid(np.arange(rows) % 2, np.arange(cols) % 2, indexing="ij")
    # a blend of a texel and its neighbours, weights 9/16, 3/16, 3/16, 1/16, is never one of the 4 values
    pattern = (base * (1.0 + 0.1 * (r + 2 * c) / 3.0)).reshape(rows, cols, 1)
    params[key] = mi.TensorXf(pattern.astype(np.float32))
    params.update()
    si = mi.SurfaceInteraction3f()
    si.uv = mi.Point2f(0.75 / cols, 0.75 / rows)
    value = float(np.asarray(node.eval_1(si)).ravel()[0])
    return not np.any(np.abs(pattern.ravel() - value) <= 1e-5 * base)


def map_loss(problem: MapProblem, values: dict, spp: int, seed0, tensors, regularizer=None, weight=0.0):
    """Step 2, the loss: render every observation (seed ``seed0 + j``) and return (loss, data, reg)
    = sum_j w_j L_j + weight * sum_maps R(map) (differentiable in ``values``)."""
    import drjit as dr
    import mitsuba as mi

    data = 0.0
    for j, (o, fn) in enumerate(zip(problem.observations, problem.losses)):
        si = problem.scene_of[j]
        S = render_stokes(problem.scenes[si], o.sensor, spp, seed0 + j, params=problem.all_params[si],
                          names=problem.channels[j])
        data = data + problem.weights[j] * fn(S, tensors[j])
    reg = dr.zeros(mi.Float, 1)
    if regularizer is not None and weight > 0:
        for name in problem.fit:
            if problem.shapes[name] is not None:
                reg = reg + weight * smoothness(values[name], regularizer)
    return data + reg, data, reg


def map_step(problem: MapProblem, spp: int, regularizer=None, weight=0.0):
    """The loss and its gradient as one function ``step(scenes, values, seed0, tensors)`` (the
    arguments a ``dr.freeze`` recording needs as inputs); the gradient lands in ``values``."""
    import drjit as dr

    def step(scenes_in, values_in, seed0, tensors_in):
        loss, data, reg = map_loss(problem, values_in, spp, seed0, tensors_in, regularizer, weight)
        dr.backward(loss)
        return loss, data, reg

    return step


class _MapAdam(LogAdam):
    """Step 3, the update: :class:`~hyde_bsdf.inverse.adam.LogAdam` over the problem's fitted maps, in
    :data:`MAP_PARAMETERS`' ranges; the values are written into every scene as gradient-enabled leaves
    (a frozen step sees them as inputs)."""

    def __init__(self, problem: MapProblem, start: dict, lr: float, iterations: int, average_last: int):
        super().__init__({n: problem.as_value(n, start[n]) for n in problem.fit},
                         {n: MAP_PARAMETERS[n][1] for n in problem.fit}, lr, iterations, average_last)
        self.problem = problem

    def values(self) -> dict:
        values = super().values()
        self.problem.write(values)
        return values

    def snapshot(self, name):
        v = super().snapshot(name)
        return v[..., 0] if self.problem.shapes[name] is not None else float(v.ravel()[0])


def map_uncertainty(problem: MapProblem, final: dict, *, spp: int = 16, seed: int = 0, noise=None,
                    polish: int = 2, threshold: float = STDERR_THRESHOLD, max_step: float = 0.25,
                    convergence: float = CONVERGENCE_THRESHOLD, regularized: bool = False,
                    extra_polish: int = 3):
    """Step 4, the uncertainty of the fitted *maps* at ``final`` (see :mod:`hyde_bsdf.inverse.uncertainty`):
    ``polish`` Gauss-Newton steps per texel (0: none) on the noise-weighted least squares (weights
    1 / variance per observation and Stokes component: the efficient estimate, which the loss's own
    normalisation is not), then the standard errors at the last point whose information was computed
    (the inverse Fisher information after polishing, with the noise estimated from the residuals
    linearised after the last step; the sandwich with the loss's weights without).

    Convergence before uncertainty: the last two Gauss-Newton steps (without polishing: the step the
    blocks predict, -A^-1 g) are measured in standard errors per texel and parameter; while one of
    them exceeds ``convergence`` in some texel, up to ``extra_polish`` more steps are taken; where it
    still does (or a step hit ``max_step``) the texel's standard error is NaN and
    ``Uncertainty.converged`` is False there (:func:`~hyde_bsdf.inverse.uncertainty.convergence_test`).
    Two steps, not one: Gauss-Newton from far away can take one small step and the next large
    (measured: a texel 9-11 standard errors off after a last step of 1.9).  Small steps do not
    show a texel the steps no longer move (a local minimum, a bound), so a texel whose value sits
    at a bound of its range, or whose residuals stay above the noise (chi-square p-value <
    :data:`~hyde_bsdf.inverse.uncertainty.MISFIT_P`), is not converged either, and a texel not
    converged in one parameter is not converged in any
    (:func:`~hyde_bsdf.inverse.uncertainty.texel_convergence`).
    A fitted bitmap that filters bilinearly couples neighbouring texels, which the per-texel blocks
    do not describe: every standard error is then NaN and ``Uncertainty.filter_valid`` False.
    Returns (final maps, :class:`Uncertainty`)."""
    names = tuple(n for n in problem.fit if problem.shapes[n] is not None)
    if not names:
        return final, None
    rows, cols = problem.map_shape
    seen = problem.seen if problem.seen is not None else np.ones((rows, cols), bool)
    final, records, blocks, steps, applied = _polish(problem, names, dict(final), spp=spp, seed=seed, noise=noise,
                                            polish=polish, max_step=max_step, seen=seen, convergence=convergence,
                                            extra=extra_polish)
    A, B, g, noise_std, n_data = blocks
    chi2, m_data = texel_misfit(records, (rows, cols), step=applied)
    problem.write({n: problem.as_value(n, final[n]) for n in problem.fit})
    rel = standard_errors(A, B, seen, dof=(n_data, len(names) * int(np.asarray(seen).sum())))
    # a texel no picture has a whole pixel inside got no information computed: unknown, not undetermined
    whole = np.zeros(rows * cols, np.int64)
    for rec in records:
        if rec is not None:
            np.add.at(whole, rec["t"], 1)
    rel[whole == 0] = np.nan
    misfit_p = misfit_pvalues(chi2, m_data, len(names))
    pinned = at_bounds(np.stack([np.ravel(final[n]) for n in names], axis=1), [MAP_PARAMETERS[n][1] for n in names])
    ok, ratio = texel_convergence(steps, rel, seen, threshold=convergence, clip=max_step if polish else None,
                                  misfit_p=misfit_p, pinned=pinned)
    shape = lambda a, i: a[:, i].reshape(rows, cols)
    rel_maps = {n: shape(rel, i) for i, n in enumerate(names)}
    found = identification_warnings(rel_maps, seen, threshold)
    unchecked = rel_maps
    rel = np.where(ok, rel, np.nan)            # an unconverged texel's standard error would understate its error
    filter_valid = not problem.bilinear
    if not filter_valid:
        rel[:] = np.nan
    rel_maps = {n: shape(rel, i) for i, n in enumerate(names)}
    unc = Uncertainty(names, {n: rel_maps[n] * np.asarray(final[n]) for n in names}, rel_maps, A, B, g, noise_std,
                      {n: f for n, (f, _) in found.items()}, threshold,
                      step_se={n: shape(ratio, i) for i, n in enumerate(names)},
                      converged={n: shape(ok, i) for i, n in enumerate(names)}, filter_valid=filter_valid,
                      unchecked=unchecked)
    unc.misfit_p = misfit_p.reshape(rows, cols)
    unc.pinned = {n: shape(pinned, i) for i, n in enumerate(names)}
    unc.messages = _uncertainty_messages(problem, unc, found, seen, convergence, regularized)
    return final, unc


def _polish(problem, names, final, *, spp, seed, noise, polish, max_step, seen, convergence, extra):
    """At least ``polish`` Gauss-Newton steps, and up to ``extra`` more while some seen texel has not
    converged (:func:`_steps_converged`: its last two steps within ``convergence`` standard errors);
    returns (final, records of the last pass, the blocks (A, B, g, noise, n) to take the standard
    errors from, and the last two steps (2, texels, P): the ones applied with polishing; without,
    the step the blocks predict, -A^-1 g, twice)."""
    rows, cols = problem.map_shape
    # with polishing steps the result is the weighted least-squares estimate (weights 1 / noise
    # variance, the efficient one); without, Adam's minimiser of the loss, whose covariance is the
    # sandwich with the loss's own weights
    weighting = "fisher" if polish else "loss"
    steps = []
    for k in range(max(1, int(polish) + int(extra) if polish else 1)):
        problem.write({n: problem.as_value(n, final[n]) for n in problem.fit})
        records = pixel_records(problem, names, spp=spp, seed=seed + 1000 * k, noise=noise)
        blocks = accumulate_blocks(records, (rows, cols), len(names), weighting=weighting)
        if not polish:
            d = gauss_newton_step(blocks[0], blocks[2], seen, max_step=np.inf)
            return final, records, blocks, np.array([d, d]), None
        d = gauss_newton_step(blocks[0], blocks[2], seen, max_step=max_step)
        steps.append(d)
        applied = np.zeros_like(d)
        for i, n in enumerate(names):
            lo, hi = MAP_PARAMETERS[n][1]
            old = np.asarray(final[n], np.float64)
            final[n] = np.clip(old * np.exp(d[:, i].reshape(rows, cols)), lo, hi)
            applied[:, i] = np.log(final[n] / old).ravel()
        if k + 1 >= polish and _steps_converged(steps, blocks, seen, convergence, max_step).all():
            break
    # the blocks after the last step, linearised (no further render): its residuals r + J d give the
    # noise estimate without the misfit the step removed
    blocks = accumulate_blocks(records, (rows, cols), len(names), weighting=weighting, step=applied)
    return final, records, blocks, np.array(steps[-2:] if len(steps) > 1 else [steps[-1]] * 2), applied


def _steps_converged(steps, blocks, seen, convergence, max_step):
    """(texels, P) bool: the last two Gauss-Newton steps (the last one alone after a single step) both
    within ``convergence`` standard errors (those of ``blocks``) and below the clip."""
    A, B, _, _, n_data = blocks
    rel = standard_errors(A, B, seen)
    ok = np.ones_like(steps[-1], bool)
    for d in steps[-2:]:
        ok &= convergence_test(d, rel, seen, convergence, clip=max_step)[0]
    return ok


def _uncertainty_messages(problem, unc, found, seen, convergence, regularized) -> list:
    """The warnings of one uncertainty step, each once: (category, message)."""
    out = [(UnidentifiedParameterWarning, m) for _, m in found.values()]
    conv = convergence_warnings(unc.converged, unc.step_se, seen, convergence, regularized)
    out += [(NotConvergedWarning, m) for _, m in conv.values()]
    if not unc.filter_valid:
        out.append((BilinearFilterWarning, f"the bitmap(s) of {', '.join(problem.bilinear)} filter bilinearly: "
                    "a pixel then blends neighbouring texels, which the per-texel standard errors do not "
                    "describe (measured 4x too small), so they are set to NaN; load the maps with "
                    "<string name=\"filter_type\" value=\"nearest\"/>"))
    return out


@dataclass(frozen=True)
class MapOptions(Options):
    """The loop and the uncertainty step of :func:`invert_maps` (each field is also a keyword of
    :func:`invert_maps`; its docstring describes them)."""

    iterations: int = 100
    lr: float = 0.05
    spp: int = 4
    seed: int = 0
    components: str = "stokes"
    regularizer: str | None = None
    weight: float = 0.0
    average_last: int | None = None
    freeze: bool = True
    uncertainty: bool = True
    uncertainty_spp: int = 16
    polish: int = 2
    threshold: float = STDERR_THRESHOLD
    convergence: float = CONVERGENCE_THRESHOLD
    extra_polish: int = 3


def invert_maps(observations, start: dict, options: MapOptions | None = None, *, fit=("alpha",),
                truth: dict | None = None, prefix: str | None = None, seen: np.ndarray | None = None, noise=None,
                progress=True, **settings) -> MapInversionResult:
    """Optimise texture-valued BSDF parameters (a roughness map, optionally index maps) to match
    one or more reference Stokes images.

    The loop's and the uncertainty step's settings are a :class:`MapOptions` (``options``), or its
    fields given as keywords (``iterations=50, spp=8``): ``iterations``, ``lr``, ``spp``, ``seed``,
    ``components``, ``regularizer``, ``weight``, ``average_last``, ``freeze``, ``uncertainty``,
    ``uncertainty_spp``, ``polish``, ``threshold``, ``convergence``, ``extra_polish`` below.

    ``observations``: list of :class:`Observation`.  ``start``: name -> start value, a float
    (a constant map) or an array (rows, cols) for texture parameters; a parameter named in
    ``start`` but not in ``fit`` is set and held fixed.  ``fit``: names from
    :data:`MAP_PARAMETERS` (texture keys ``NAME.data`` are fitted per texel, constants
    ``NAME.value`` as one number).  Loss::

        L = sum_i w_i L_i / sum_i w_i  +  weight * R(map)

    with L_i the :class:`StokesLoss` of observation i (``components`` "stokes" or "s0") and R the
    :func:`smoothness` of each fitted map (``regularizer`` "tv" or "l2"; off when None or
    ``weight`` = 0).  L_i is dimensionless (1 = a render as far from the reference as black is);
    R is in map units (tv) or their square (l2), so ``weight`` converts map differences into loss
    units: a step of height d between two neighbours costs ``weight * d / n_pairs`` (tv) or
    ``weight * d**2 / n_pairs`` (l2).  Both terms scale alike with the map's and the images'
    resolution, so the weight carries over.  Measured on an 8 x 8 alpha map (gradient + a step,
    2 views x 2 lights, 24 iterations; "flatness" = the fit's mean neighbour difference / the
    truth's): tv 0.01 -> 1.03 (no effect), 0.1 -> 0.96, 1 -> 0.60, 10 -> 0.36 (over-smoothed,
    median error 1.5 % -> 8 %); l2 0.1 -> 1.02, 1 -> 0.87, 10 -> 0.63, 100 -> 0.48.  Use it to
    fill texels that the images barely constrain (tv ~ 0.1 keeps edges; l2 rounds them).

    Adam on log(value) per texel (values stay positive; one learning rate fits every texel),
    clamped to :data:`MAP_PARAMETERS`' ranges; lr constant for the first half, then decaying
    geometrically to lr/10; iteration i renders observation j with seed
    ``seed + 1 + i * len(observations) + j``.  The final maps are the mean of the iterates over
    the last ``average_last`` iterations (default: a quarter; Polyak averaging).  ``seen`` (or,
    by default, the union of :func:`texel_coverage` over the observations) marks the texels that
    the images see; with ``truth`` the history records the median and 90th-percentile relative
    error of each fitted map over them.  ``freeze=True`` (default) runs each step (renders, loss,
    backward) as a ``dr.freeze`` function: recorded on the first iteration, then replayed, which
    removes the per-iteration Python tracing of the integrator and the BSDF (identical results:
    measured max |difference| 5e-8 in alpha after 10 iterations; ~8x faster per iteration on the
    8 x 8 test problem).  If Dr.Jit cannot record the step (a scene object it cannot traverse)
    the run continues unfrozen, with a note on stderr.

    Uncertainty (``uncertainty=True``, the default, for every fitted texture; see
    :mod:`hyde_bsdf.inverse.uncertainty`): after the last iteration, per-texel blocks of the
    Gauss-Newton information from forward-mode AD at ``uncertainty_spp`` samples, ``polish``
    Gauss-Newton steps per texel from the averaged iterate (default 2; 0 skips them, as a
    regulariser does, which the steps do not know), and the standard errors ``result.stderr`` / ``result.rel_stderr``
    (maps; NaN where unseen).  A parameter whose relative standard error exceeds ``threshold``
    in some seen texels raises an :class:`~hyde_bsdf.inverse.uncertainty.UnidentifiedParameterWarning`
    naming it and the fraction of texels (also in ``result.warnings``).  ``noise``: the references'
    noise standard deviation per observation (a number or 4 numbers, S0..S3) when known; otherwise
    estimated from the residuals.  Convergence is tested before the standard errors are reported:
    while the last two Gauss-Newton steps of some texel exceed ``convergence`` standard errors, up to
    ``extra_polish`` more steps are taken (:func:`map_uncertainty`); where they still do the texel
    has not reached the minimum, its standard error is NaN, ``result.converged[name]`` is False there and a
    :class:`~hyde_bsdf.inverse.uncertainty.NotConvergedWarning` names the parameter and the
    fraction of texels.  A fitted bitmap that filters bilinearly (Mitsuba's default) is switched to
    ``filter_type`` ``nearest`` in the given scenes (they are changed in place:
    :func:`~hyde_bsdf.render.texture_filter.bitmap_to_nearest`), with one
    :class:`~hyde_bsdf.inverse.uncertainty.BilinearFilterWarning`; a BSDF that cannot take the swap
    (only the ``hyde`` plugin can) keeps its bilinear bitmap and gets NaN standard errors and that
    warning instead.  Each warning is issued once.

    The steps, each its own function: :meth:`MapProblem.build` (observation set-up: checks, losses,
    traverse keys, texel coverage), :func:`map_loss` (renders and the loss), :func:`map_step` (the
    loss and its gradient, the frozen function), :class:`~hyde_bsdf.inverse.adam.LogAdam` (the update in log values,
    the learning-rate schedule, the average), :func:`map_uncertainty` (the information, the polish, the
    standard errors and warnings).
    """
    o = MapOptions.of(options, settings, "invert_maps")
    iterations, seed, regularizer, weight = o.iterations, o.seed, o.regularizer, o.weight
    _check_options(iterations, regularizer, weight)
    progress = as_callback(progress, "[invert]")
    problem = MapProblem.build(observations, start, fit, components=o.components, prefix=prefix, seen=seen)
    n_obs = len(problem.observations)
    average_last = max(1, iterations // 4) if o.average_last is None else max(1, int(o.average_last))
    adam = _MapAdam(problem, start, o.lr, iterations, average_last)
    truth_np = {n: np.asarray(v, np.float64) for n, v in (truth or {}).items()}
    history, t_first = _adam_loop(problem, adam, map_step(problem, o.spp, regularizer, weight), iterations=iterations,
                                  seed=seed, freeze=o.freeze, truth_np=truth_np, progress=progress)
    final = adam.average()
    adam_final = dict(final)
    # the scenes keep the result, detached: the last iteration's gradient-enabled leaves must not
    # outlive the run (a later forward-mode pass, here or in the caller's next problem, would
    # otherwise reach their edges from inside mi.render's isolated AD scope and fail)
    problem.write({n: problem.as_value(n, final[n]) for n in problem.fit})
    unc = None
    if o.uncertainty:
        regularized = regularizer is not None and weight > 0
        if progress:
            progress(f"uncertainty: forward-mode information of {', '.join(problem.fit)} at {o.uncertainty_spp} spp"
                     + (f", {o.polish} Gauss-Newton step(s)" if o.polish and not regularized else ""))
        final, unc = map_uncertainty(problem, final, spp=o.uncertainty_spp, seed=seed + 1 + iterations * n_obs,
                                     noise=noise, polish=0 if regularized else o.polish, threshold=o.threshold,
                                     convergence=o.convergence, extra_polish=o.extra_polish, regularized=regularized)
    for n in problem.names:
        if n not in problem.fit:
            final[n] = np.asarray(start[n], np.float64) if np.ndim(start[n]) else float(start[n])
    res = MapInversionResult(fitted=problem.fit, final=final, start=dict(start), components=o.components,
                             seen=problem.seen, truth=truth, history=history,
                             seconds_per_iteration=seconds_per_iteration(history), first_iteration_seconds=t_first,
                             adam_final=adam_final, uncertainty=unc)
    _attach_warnings(res, problem, unc)
    return res


def _check_options(iterations, regularizer, weight) -> None:
    """One-line UsageErrors for invert_maps' loop options."""
    if not (isinstance(iterations, int) and iterations >= 1):
        raise UsageError(f"iterations must be an integer >= 1, got {iterations!r}")
    if regularizer not in (None, "tv", "l2"):
        raise UsageError(f"regularizer must be None, 'tv' or 'l2', got {regularizer!r}")
    if not (math.isfinite(weight) and weight >= 0):
        raise UsageError(f"weight must be a finite number >= 0, got {weight!r}")


def _adam_loop(problem, adam, step, *, iterations, seed, freeze, truth_np, progress):
    """Steps 2 and 3, ``iterations`` times: the loss and its gradient (``step``, frozen when ``freeze``),
    the Adam update; returns (history rows, seconds of the first iteration)."""
    import drjit as dr
    import mitsuba as mi

    # dr.freeze records the step's kernels once and replays them (no Python re-tracing of the
    # integrator and the BSDF per iteration); results equal the unfrozen step's
    step_fn = freeze_step(step) if freeze else step
    tensors = [fn.tensors for fn in problem.losses]
    history, t0, t_first = [], time.perf_counter(), None
    for it in range(iterations):
        t_it = time.perf_counter()
        seed_it = dr.opaque(mi.UInt32, seed + 1 + it * len(problem.observations))
        terms, values, step_fn = _gradient(problem, adam, step, step_fn, seed_it, tensors, it)
        row = {"iteration": it, **{k: float(np.asarray(v).ravel()[0])
                                   for k, v in zip(("loss", "data_loss", "regularizer"), terms)}}
        if not math.isfinite(row["loss"]):
            raise FloatingPointError(f"the loss became {row['loss']} at iteration {it}")
        row.update(_map_errors(adam.step(it, values), truth_np, problem.seen))
        t_first = record_iteration(row, history, t0, t_it, t_first)
        if progress:
            err = "".join(f"  {n} median err {100 * row[n + '_median_error']:.1f} %" for n in problem.fit
                          if n + "_median_error" in row)
            progress(f"it {it + 1:4d}/{iterations}  loss {row['loss']:.4e}{err}  ({row['seconds']:.1f} s)")
    return history, t_first


def _gradient(problem, adam, step, step_fn, seed_it, tensors, it):
    """One evaluation of the loss and its gradient: ((loss, data, reg), the values holding the gradient,
    the step function to use from now on -- the unfrozen one when Dr.Jit could not record the step)."""
    try:
        values = adam.values()
        return step_fn(problem.scenes, values, seed_it, tensors), values, step_fn
    except RuntimeError as exc:
        if step_fn is step or it > 0:
            raise
        # a scene object Dr.Jit cannot traverse (a custom plugin without traverse support):
        # run unfrozen, which gives the same results, only slower
        warnings.warn(f"dr.freeze could not record the step ({_first_line(exc)}); running unfrozen",
                      RuntimeWarning, stacklevel=4)
        values = adam.values()
        return step(problem.scenes, values, seed_it, tensors), values, step


def _map_errors(current: dict, truth_np: dict, seen) -> dict:
    """{NAME_median_error, NAME_p90_error} of the iterate ``current`` against the known truth maps."""
    row = {}
    for n in truth_np:
        if n in current and np.ndim(current[n]) == 2:
            rel = np.abs(current[n] / truth_np[n] - 1.0)
            rel = rel[seen] if seen is not None else rel.ravel()
            row[f"{n}_median_error"] = float(np.median(rel))
            row[f"{n}_p90_error"] = float(np.percentile(rel, 90))
    return row


def _attach_warnings(res, problem, unc) -> None:
    """The result's standard errors and its warnings (each issued once, also kept in ``res.warnings``)."""
    messages = [(BilinearFilterWarning, _nearest_message(problem.nearest))] if problem.nearest else []
    if unc is not None:
        res.stderr, res.rel_stderr, res.converged = unc.stderr, unc.rel_stderr, unc.converged
        messages += unc.messages
    res.messages = messages
    res.warnings = [m for _, m in messages]
    for category, message in messages:        # each once
        warnings.warn(message, category, stacklevel=3)


def _nearest_message(names) -> str:
    """The one warning for fitted bitmaps switched from bilinear to nearest."""
    return (f"the bitmap(s) of {', '.join(names)} filtered bilinearly (Mitsuba's default): they were switched "
            "to filter_type nearest in the given scenes and fitted so (a bilinear pixel blends 4 texels, which "
            "the per-texel fit and its standard errors do not describe); write "
            "<string name=\"filter_type\" value=\"nearest\"/> in the scene to render what was fitted")
