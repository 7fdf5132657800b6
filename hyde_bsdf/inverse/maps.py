"""Texture-valued (SVBRDF) inverse rendering: per-texel roughness and index maps from several
Stokes images (:func:`invert_maps`).

May import: the other modules of ``hyde_bsdf.inverse`` except ``cli``.
"""
from __future__ import annotations

import gc
import math
import time
from dataclasses import dataclass, field

import numpy as np

from hyde_bsdf.inverse._common import _first_line, _log
from hyde_bsdf.inverse.loss import StokesLoss, smoothness
from hyde_bsdf.inverse.scalar import check_gradients
from hyde_bsdf.inverse.observations import (MAP_PARAMETERS, _obs_mask, film_channels, map_keys,
                                            render_stokes, texel_coverage)

__all__ = ["MapInversionResult", "invert_maps"]


@dataclass
class MapInversionResult:
    """Outcome of :func:`invert_maps`: final maps/values (NumPy), per-iteration history, texel mask."""

    fitted: tuple
    final: dict                      # name -> ndarray (rows, cols) for maps, float for constants
    start: dict
    components: str
    seen: np.ndarray | None = None   # bool (rows, cols): texels some observation sees
    truth: dict | None = None
    history: list = field(default_factory=list)  # iteration, loss, data_loss, regularizer, seconds, [errors]
    seconds_per_iteration: float = float("nan")
    first_iteration_seconds: float = float("nan")

    def texel_errors(self, name: str = "alpha") -> np.ndarray:
        """|final / truth - 1| over the seen texels of map ``name`` (1-D array)."""
        if not self.truth or name not in self.truth:
            raise ValueError(f"no truth for {name!r}")
        rel = np.abs(np.asarray(self.final[name]) / np.asarray(self.truth[name]) - 1.0)
        return rel[self.seen] if self.seen is not None and rel.shape == self.seen.shape else rel.ravel()


def invert_maps(observations, start: dict, *, fit=("alpha",), iterations: int = 100, lr: float = 0.05,
                spp: int = 4, seed: int = 0, components: str = "stokes", regularizer: str | None = None,
                weight: float = 0.0, truth: dict | None = None, prefix: str | None = None,
                average_last: int | None = None, progress: bool = True,
                seen: np.ndarray | None = None, freeze: bool = True) -> MapInversionResult:
    """Optimise texture-valued BSDF parameters (a roughness map, optionally index maps) to match
    one or more reference Stokes images.

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
    """
    import drjit as dr
    import mitsuba as mi

    observations = list(observations)
    if not observations:
        raise ValueError("observations must hold at least one Observation")
    fit = tuple(fit)
    if not fit:
        raise ValueError(f"fit must name at least one of {tuple(MAP_PARAMETERS)}")
    for name in fit:
        if name not in MAP_PARAMETERS:
            raise ValueError(f"fit: unknown parameter {name!r}; use {', '.join(MAP_PARAMETERS)}")
        if name not in start:
            raise ValueError(f"start must give a value for every fitted parameter; missing {name!r}")
    if not (isinstance(iterations, int) and iterations >= 1):
        raise ValueError(f"iterations must be an integer >= 1, got {iterations!r}")
    if regularizer not in (None, "tv", "l2"):
        raise ValueError(f"regularizer must be None, 'tv' or 'l2', got {regularizer!r}")
    if not (math.isfinite(weight) and weight >= 0):
        raise ValueError(f"weight must be a finite number >= 0, got {weight!r}")
    for o in observations:
        ref = np.asarray(o.reference)
        if ref.ndim != 3 or ref.shape[0] != 4:
            raise ValueError(f"reference must have shape (4, H, W), got {ref.shape}")
        W, H = o.scene.sensors()[int(o.sensor)].film().crop_size()
        if ref.shape[1:] != (H, W):
            raise ValueError(f"reference is {ref.shape[2]}x{ref.shape[1]} pixels but sensor {o.sensor}'s "
                             f"film is {W}x{H}")
        if not np.isfinite(ref).all():
            raise ValueError("reference contains NaN or infinite pixels")
    losses = [StokesLoss(o.reference, mask=_obs_mask(o), components=components) for o in observations]
    wsum = float(sum(o.weight for o in observations))
    if not wsum > 0:
        raise ValueError("the observations' weights must sum to > 0")

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

    def as_value(name, v):
        lo, hi = MAP_PARAMETERS[name][1]
        if shapes[name] is None:
            return mi.Float(float(np.clip(float(np.mean(v)), lo, hi)))
        arr = np.broadcast_to(np.asarray(v, np.float64).reshape(shapes[name][:2] + (1,))
                              if np.ndim(v) else np.asarray(v, np.float64), shapes[name])
        return mi.TensorXf(np.clip(arr, lo, hi).astype(np.float32))

    if seen is None:
        map_shape = next((shapes[n][:2] for n in fit if shapes[n] is not None), None)
        if map_shape is not None:
            cover = sum(texel_coverage(o, map_shape, prefix) for o in observations)
            seen = cover > 0

    for name in names:
        try:
            value = as_value(name, start[name])
        except ValueError:
            raise ValueError(f"start[{name!r}] must be a number or an array of the texture's shape "
                             f"{shapes[name][:2]}") from None
        for p, k in zip(all_params, keys):
            p[k[name]] = value
    for p in all_params:
        p.update()

    # beta_2 = 0.9 (not Adam's 0.999): a texel's gradient falls by orders of magnitude as it
    # converges, and a long memory of the early large gradients stalls it (measured: with 0.999 the
    # alpha = 0.6 square of the validation map sat 11 % high after 60 iterations; with 0.9, < 1 %);
    # beta_1 = 0.8: less momentum, less overshoot of the texels that move far
    opt = mi.ad.Adam(lr=lr, beta_1=0.8, beta_2=0.9)
    for name in fit:
        opt[name] = dr.log(as_value(name, start[name]))
    truth_np = {n: np.asarray(v, np.float64) for n, v in (truth or {}).items()}

    def snapshot(name):
        v = np.exp(np.asarray(opt[name], dtype=np.float64))
        return v[..., 0] if shapes[name] is not None else float(v.ravel()[0])

    scene_of = [next(i for i, s in enumerate(scenes) if s is o.scene) for o in observations]
    channels = [film_channels(o.scene, o.sensor) for o in observations]

    def step(scenes_in, values_in, seed0, tensors_in):
        """Render every observation, the loss, and its gradient (into ``values_in``)."""
        data = 0.0
        for j, (o, fn) in enumerate(zip(observations, losses)):
            S = render_stokes(scenes_in[scene_of[j]], o.sensor, spp, seed0 + j, params=all_params[scene_of[j]],
                              names=channels[j])
            data = data + (o.weight / wsum) * fn(S, tensors_in[j])
        reg = dr.zeros(mi.Float, 1)
        if regularizer is not None and weight > 0:
            for name in fit:
                if shapes[name] is not None:
                    reg = reg + weight * smoothness(values_in[name], regularizer)
        loss = data + reg
        dr.backward(loss)
        return loss, data, reg

    # dr.freeze records the step's kernels once and replays them (no Python re-tracing of the
    # integrator and the BSDF per iteration); results equal the unfrozen step's
    step_fn = dr.freeze(step) if freeze else step

    def set_values():
        # the render differentiates with respect to the value itself (a leaf, so that a frozen
        # step sees it as an input); the chain rule to log(value) is applied after the step
        values = {}
        for name in fit:
            values[name] = dr.exp(dr.detach(opt[name]))
            dr.enable_grad(values[name])
        for p, k in zip(all_params, keys):
            for name in fit:
                p[k[name]] = values[name]
            p.update()
        return values
    history, sums, n_avg = [], {}, 0
    average_last = max(1, iterations // 4) if average_last is None else max(1, int(average_last))
    t0 = time.perf_counter()
    t_first = None
    n_obs = len(observations)
    for it in range(iterations):
        t_it = time.perf_counter()
        if it >= iterations // 2:
            # geometric decay from lr (half-way) to lr/10 (last iteration)
            span = max(1, iterations - 1 - iterations // 2)
            opt.set_learning_rate(lr * 0.1 ** ((it - iterations // 2) / span))
        for name in fit:
            lo, hi = MAP_PARAMETERS[name][1]
            opt[name] = dr.clip(opt[name], math.log(lo), math.log(hi))
        seed_it = dr.opaque(mi.UInt32, seed + 1 + it * n_obs)
        try:
            values = set_values()
            if step_fn is not step:
                # release what is pending first: arrays made from NumPy memory and waiting for
                # the garbage collector are freed through host callbacks, which a recording
                # cannot hold (Dr.Jit aborts the process)
                gc.collect()
                dr.sync_thread()
            loss, data, reg = step_fn(scenes, values, seed_it, [fn.tensors for fn in losses])
        except RuntimeError as exc:
            if step_fn is step or it > 0:
                raise
            # a scene object Dr.Jit cannot traverse (a custom plugin without traverse support):
            # run unfrozen, which gives the same results, only slower
            _log(f"dr.freeze could not record the step ({_first_line(exc)}); running unfrozen")
            step_fn = step
            values = set_values()
            loss, data, reg = step_fn(scenes, values, seed_it, [fn.tensors for fn in losses])
        for name in fit:
            dr.set_grad(opt[name], dr.grad(values[name]) * dr.detach(values[name]))
        check_gradients({n: dr.grad(opt[n]) for n in fit}, it)
        row = {"iteration": it, "loss": float(np.asarray(loss).ravel()[0]),
               "data_loss": float(np.asarray(data).ravel()[0]),
               "regularizer": float(np.asarray(reg).ravel()[0])}
        if not math.isfinite(row["loss"]):
            raise FloatingPointError(f"the loss became {row['loss']} at iteration {it}")
        current = {n: snapshot(n) for n in fit}
        for n in truth_np:
            if n in current and np.ndim(current[n]) == 2:
                rel = np.abs(current[n] / truth_np[n] - 1.0)
                rel = rel[seen] if seen is not None else rel.ravel()
                row[f"{n}_median_error"] = float(np.median(rel))
                row[f"{n}_p90_error"] = float(np.percentile(rel, 90))
        opt.step()
        if it >= iterations - average_last:
            for n in fit:
                sums[n] = sums.get(n, 0.0) + current[n]
            n_avg += 1
        dt = time.perf_counter() - t_it
        if t_first is None:
            t_first = dt
        row["seconds"] = time.perf_counter() - t0
        history.append(row)
        if progress:
            err = "".join(f"  {n} median err {100 * row[n + '_median_error']:.1f} %" for n in fit
                          if n + "_median_error" in row)
            _log(f"it {it + 1:4d}/{iterations}  loss {row['loss']:.4e}{err}  ({row['seconds']:.1f} s)")
    final = {n: sums[n] / n_avg for n in fit}
    for n in names:
        if n not in fit:
            final[n] = np.asarray(start[n], np.float64) if np.ndim(start[n]) else float(start[n])
    per_it = ((history[-1]["seconds"] - history[0]["seconds"]) / (len(history) - 1)
              if len(history) > 1 else float("nan"))
    return MapInversionResult(fitted=fit, final=final, start=dict(start), components=components, seen=seen,
                              truth=truth, history=history, seconds_per_iteration=per_it,
                              first_iteration_seconds=t_first)


# the SVBRDF scene: a textured plane, three views in one batch sensor, one point light per scene
