"""Differentiable inverse rendering of one global roughness and index (scalars) from a Stokes image.

A reference Stokes image of a scene with the ``hyde`` BSDF is matched by a
rendering whose BSDF parameters (``rms_slope``, ``eta``, ``k``; any subset) are
optimized with Mitsuba's ``mi.ad.Adam`` through the ``stokes`` integrator around
``path`` (``prb`` inside ``stokes`` gives the same gradients, bare ``prb`` fails in
polarized variants; ``path`` differentiates through ``mi.render(scene, params, spp=..., seed=...)`` and
``dr.backward``) in ``llvm_ad_spectral_polarized``, with the loss of :mod:`hyde_bsdf.inverse.loss`.

Parameters are optimized as their logarithms (so they stay positive and one
learning rate fits all), clamped to the plugin's accepted range, with the
learning rate decaying geometrically over the last quarter.  Each iteration renders
with a new seed (``seed + 1 + iteration``); the reference uses ``seed`` and
``spp_ref`` samples.

Index convention: the plugin's ``eta``, ``k`` are Mitsuba's n + ik; the paper's
eta = n - jk describes the same material with the same numbers.
"""
from __future__ import annotations

import math
import time
import warnings
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from hyde_bsdf.errors import UsageError, shorten
from hyde_bsdf.inverse._common import NotConvergedWarning, freeze_step, record_iteration, write_history
from hyde_bsdf.inverse.adam import LogAdam, check_gradients
from hyde_bsdf.options import Options
from hyde_bsdf.progress import as_callback
from hyde_bsdf.inverse.loss import StokesLoss, channel_names, stokes_images
from hyde_bsdf.model.parameters import INVERSE_ETA, INVERSE_K, INVERSE_PARAMETERS, RMS_SLOPE, SQRT2

__all__ = ["InversionOptions", "VARIANT", "PARAMETERS", "INVERSE_PARAMETERS", "TRUTH", "START", "RANGES", "prepare", "scene_dict",
           "load_scene", "parameter_keys", "render_reference", "InversionResult", "invert", "trajectory_converged",
           "check_gradients", "loss_and_gradient", "finite_difference_gradient"]

VARIANT = "llvm_ad_spectral_polarized"
#: optimizable BSDF parameters (``parameters.INVERSE_PARAMETERS``: the plugin's names, Mitsuba's n + ik)
PARAMETERS = INVERSE_PARAMETERS
#: ground truth and a start far from it used by the scripts and the CLI by default
TRUTH = {"rms_slope": 0.3, "eta": 1.5, "k": 3.0}
START = {"rms_slope": 0.6, "eta": 3.0, "k": 6.0}
#: the optimisation box (``hyde_bsdf.model.parameters``): rms_slope the accepted range, eta and k a sane box
RANGES = {"rms_slope": RMS_SLOPE.bounds, "eta": INVERSE_ETA.bounds, "k": INVERSE_K.bounds}


def prepare(variant: str = VARIANT) -> str:
    """Select the (LLVM-checked) variant and register ``hyde``; returns the variant set."""
    import mitsuba as mi

    from hyde_bsdf import register
    from hyde_bsdf.mitsuba.variants import set_variant

    if mi.variant() != variant:
        variant = set_variant(variant)
    register()
    if not mi.variant().endswith("_polarized") or "_ad_" not in mi.variant():
        raise RuntimeError(f"inverse rendering needs an AD polarized variant; got {mi.variant()!r} "
                           f"(is libLLVM >= 16 installed?)")
    return mi.variant()


def scene_dict(*, bsdf: str = "hyde", rms_slope: float = 0.3, eta: float = 1.5, k: float = 3.0,
               res: int = 64, spp: int = 16, diffuse: str = "paper", sampler: str = "multijitter",
               lighting: str = "points", phase_deg: float = 120.0) -> dict:
    """The inverse-rendering scene (as hyde_bsdf/data/scenes/inverse.xml) as a ``mi.load_dict`` dict.

    ``lighting="points"``: two point lights (front and back; facet angles beta ~ 10-70 deg
    over the image, as hyde_bsdf/data/scenes/inverse.xml).  ``lighting="directional"``: one distant light
    at ``phase_deg`` from the viewing direction, so that every pixel sees nearly the same
    facet angle beta = phase_deg / 2 (the identifiability study: S0 then measures one
    reflectance value, too little for two unknowns n, k).

    ``bsdf="roughconductor"`` swaps in Mitsuba's conductor with alpha = sqrt(2) rms_slope
    (Beckmann, the same eta, k) for comparisons.  Shape id ``sphere``.
    """
    import mitsuba as mi

    if bsdf == "hyde":
        material = {"type": "hyde", "rms_slope": float(rms_slope), "eta": float(eta), "k": float(k),
                    "diffuse": diffuse}
    elif bsdf == "roughconductor":
        material = {"type": "roughconductor", "distribution": "beckmann",
                    "alpha": SQRT2 * float(rms_slope), "eta": float(eta), "k": float(k)}
    else:
        raise UsageError(f"bsdf must be 'hyde' or 'roughconductor', got {shorten(bsdf)}")
    if lighting == "points":
        lights = {"light_front": {"type": "point", "position": [-1.5, 0.8, 3.0],
                                  "intensity": {"type": "spectrum", "value": 15.0}},
                  "light_back": {"type": "point", "position": [2.5, -0.3, -1.2],
                                 "intensity": {"type": "spectrum", "value": 25.0}}}
    elif lighting == "directional":
        ph = math.radians(float(phase_deg))
        lights = {"light": {"type": "directional", "direction": [-math.sin(ph), 0.0, -math.cos(ph)],
                            "irradiance": {"type": "spectrum", "value": 3.0}}}
    else:
        raise UsageError(f"lighting must be 'points' or 'directional', got {shorten(lighting)}")
    return {
        "type": "scene",
        "integrator": {"type": "stokes", "integrator": {"type": "path", "max_depth": 2}},
        "sensor": {"type": "perspective", "fov": 20,
                   "to_world": mi.ScalarTransform4f().look_at(origin=[0, 0, 6], target=[0, 0, 0],
                                                              up=[0, 1, 0]),
                   "film": {"type": "hdrfilm", "width": int(res), "height": int(res),
                            "rfilter": {"type": "box"}},
                   "sampler": {"type": sampler, "sample_count": int(spp)}},
        "sphere": {"type": "sphere", "bsdf": material},
        **lights,
    }


def load_scene(path=None, **kwargs):
    """Load ``path`` (XML; ``kwargs`` fill its $-defaults) or, with no path, :func:`scene_dict`."""
    import mitsuba as mi

    if path is None:
        return mi.load_dict(scene_dict(**kwargs))
    from hyde_bsdf.render.renderer import load_scene as _load

    return _load(path, {k: v for k, v in kwargs.items()})


def parameter_keys(params, names=PARAMETERS, prefix: str | None = None) -> dict:
    """Map plugin parameter names to ``mi.traverse`` keys of the one target BSDF.

    Looks for keys ending in ``.rms_slope.value`` (``hyde``; ``.alpha.value`` for
    roughconductor), ``.eta.value`` and ``.k.value``; ``prefix`` (e.g. ``"sphere.bsdf"``)
    picks one BSDF when the scene has several.
    """
    suffix = {"rms_slope": (".rms_slope.value", ".alpha.value"), "eta": (".eta.value",), "k": (".k.value",)}
    out = {}
    for name in names:
        if name not in suffix:
            raise UsageError(f"parameter names must be from {PARAMETERS}, got {shorten(name)}")
        out[name] = _unique_key(params, name, [suffix[name]], prefix)
    return out


def _unique_key(params, name, suffix_groups, prefix):
    """The one traverse key ending in a suffix of the first group that matches any key (under
    ``prefix`` if given); UsageError naming ``name``, the suffixes and the keys found otherwise."""
    found = []
    for group in suffix_groups:
        found = [key for key in params.keys() if key.endswith(group)
                 and (prefix is None or key.startswith(prefix + "."))]
        if found:
            break
    if len(found) != 1:
        suffixes = [s for group in suffix_groups for s in group]
        raise UsageError(f"need exactly one BSDF parameter for {name!r} "
                         f"(keys ending in {' or '.join(suffixes)}"
                         f"{'' if prefix is None else ' under ' + shorten(prefix)}); found {found}"
                         f"{'; name the BSDF with `prefix`' if len(found) > 1 else ''}")
    return found[0]


def _set(params, keys, values, bsdf="hyde"):
    for name, v in values.items():
        # roughconductor's roughness is Beckmann alpha = sqrt(2) rms_slope
        params[keys[name]] = v * SQRT2 if (name == "rms_slope" and bsdf == "roughconductor") else v
    params.update()


def render_reference(scene, values: dict, spp: int, seed: int = 0, bsdf="hyde", prefix=None) -> np.ndarray:
    """Luminance Stokes images (4, H, W) (float64) of ``scene`` with the BSDF set to ``values``."""
    import mitsuba as mi

    params = mi.traverse(scene)
    _set(params, parameter_keys(params, tuple(values), prefix), values, bsdf)
    img = mi.render(scene, spp=int(spp), seed=int(seed))
    return np.array([np.asarray(s, dtype=np.float64)
                     for s in stokes_images(img, channel_names(scene))])


@dataclass
class InversionResult:
    """Trajectory and outcome of :func:`invert` (``history`` rows: one per iteration)."""

    fitted: tuple
    start: dict
    final: dict
    truth: dict | None
    components: str
    history: list = field(default_factory=list)   # dicts: iteration, loss, seconds, params...
    seconds_per_iteration: float = float("nan")
    first_iteration_seconds: float = float("nan")
    converged: dict = field(default_factory=dict)  # fitted name -> bool (:func:`trajectory_converged`)
    warnings: list = field(default_factory=list)   # the NotConvergedWarning messages, each once

    def relative_errors(self) -> dict:
        if not self.truth:
            return {}
        return {n: (self.final[n] - self.truth[n]) / self.truth[n] for n in self.fitted}

    def write_history(self, path) -> Path:
        """CSV: one row per iteration (iteration, loss, seconds, parameters), after a comment line."""
        return write_history(path, self.history, ["iteration", "loss", "seconds", *PARAMETERS],
                             f"loss={self.components}; truth={self.truth}; start={self.start}; "
                             f"final (mean of the last iterations)={self.final}")


def _check_invert_args(fit, start, iterations):
    """The fitted names in PARAMETERS order; UsageError for an empty fit, a start missing a parameter or a
    bad iteration count."""
    fit = tuple(p for p in PARAMETERS if p in fit)
    if not fit:
        raise UsageError(f"fit must name at least one of {PARAMETERS}")
    missing = [p for p in PARAMETERS if p not in start]
    if missing:
        raise UsageError(f"start must give a value for every parameter; missing {missing}")
    if not (isinstance(iterations, int) and iterations >= 1):
        raise UsageError(f"iterations must be an integer >= 1, got {shorten(iterations)}")
    return fit


def _log_adam(start, fit, lr, iterations, average_last):
    """The optimiser (:class:`~hyde_bsdf.inverse.adam.LogAdam`) of the fitted parameters, from ``start``
    clamped into RANGES (floored at 1e-6: log values)."""
    import mitsuba as mi

    ranges = {p: (max(RANGES[p][0], 1e-6), RANGES[p][1]) for p in fit}
    return LogAdam({p: mi.Float(min(max(float(start[p]), ranges[p][0]), ranges[p][1])) for p in fit}, ranges, lr,
                   iterations, average_last)


def _apply_values(values, params, keys, bsdf):
    """Set the values into the scene (roughconductor takes alpha = sqrt(2) rms_slope) and update."""
    for p, v in values.items():
        params[keys[p]] = v * SQRT2 if p == "rms_slope" and bsdf == "roughconductor" else v
    params.update()


def _loss_step(params, loss_fn, names, spp: int, freeze: bool):
    """One iteration's loss and gradient as ``step(scene, values, seed, tensors)``: render, the loss of the
    Stokes images, ``dr.backward`` (the gradients land in ``values``).  ``freeze``: the step as a ``dr.freeze``
    function, recorded at the first call and replayed after (no Python re-tracing of the integrator and the BSDF;
    the same results; rgb and mono variants only: Dr.Jit cannot record a spectral one's step with ``hyde``).
    The arguments are what a recording needs as inputs; ``seed`` an opaque ``mi.UInt32`` when frozen."""
    import drjit as dr
    import mitsuba as mi

    def step(scene, values, seed, tensors):
        img = mi.render(scene, params, spp=spp, seed=seed)
        loss = loss_fn(stokes_images(img, names), tensors)
        dr.backward(loss)
        return loss

    return freeze_step(step) if freeze else step


def _history_row(loss, values, fit, it):
    """The iteration's history row (loss and fitted values); FloatingPointError for a non-finite loss."""
    row = {"iteration": it, "loss": float(np.asarray(loss).ravel()[0])}
    row.update({p: float(np.asarray(values[p]).ravel()[0]) for p in fit})
    if not math.isfinite(row["loss"]):   # never hand back a NaN trajectory silently
        raise FloatingPointError(f"the loss became {row['loss']} at iteration {it} with "
                                 + ", ".join(f"{p}={row[p]:.6g}" for p in fit))
    return row


def _inversion_result(history, fit, fixed, start, truth, loss_fn, average_last, t_first):
    """The InversionResult: each fitted parameter's mean over the last ``average_last`` iterations (Polyak
    averaging), its convergence on that window, a NotConvergedWarning for one still drifting (pointing at
    the caller of :func:`invert`)."""
    tail = history[-min(average_last, len(history)):]
    final = {p: float(np.mean([r[p] for r in tail])) for p in fit}
    final.update(fixed)
    per_it = ((history[-1]["seconds"] - history[0]["seconds"]) / (len(history) - 1)
              if len(history) > 1 else float("nan"))
    result = InversionResult(fitted=fit, start=dict(start), final=final, truth=truth,
                             components=loss_fn.components, history=history,
                             seconds_per_iteration=per_it, first_iteration_seconds=t_first)
    for p in fit:
        result.converged[p], message = trajectory_converged([r[p] for r in tail], p)
        if message:
            result.warnings.append(message)
            warnings.warn(message, NotConvergedWarning, stacklevel=3)
    return result


@dataclass(frozen=True)
class InversionOptions(Options):
    """The loop of :func:`invert` (each field is also a keyword of :func:`invert`)."""

    iterations: int = 200
    lr: float = 0.05
    spp: int = 16
    seed: int = 0
    average_last: int = 20
    freeze: bool = False


def invert(scene, loss_fn: StokesLoss, start: dict, options: InversionOptions | None = None, *, fit=PARAMETERS,
           truth: dict | None = None, bsdf: str = "hyde", prefix: str | None = None, progress=True,
           **settings) -> InversionResult:
    """Optimize the BSDF parameters ``fit`` of ``scene`` to minimize ``loss_fn``.

    The loop's settings are an :class:`InversionOptions` (``options``), or its fields given as
    keywords: ``iterations`` (200), ``lr`` (0.05), ``spp`` (16), ``seed`` (0), ``average_last`` (20),
    ``freeze`` (False: True records the step once with ``dr.freeze`` and replays it, the same results in a
    fraction of the time; rgb and mono variants only, not the default spectral one).

    ``start`` gives every parameter's start value (the unfitted ones stay there).
    Adam on log(parameter) (:class:`~hyde_bsdf.inverse.adam.LogAdam`: lr constant for the first half,
    then decaying geometrically to lr/10); iteration i renders ``spp`` samples with seed ``seed + 1 + i``.  The final value
    is the mean of the parameters over the last ``average_last`` iterations
    (Polyak averaging: it cancels the Monte-Carlo jitter of single steps).  Before it is reported,
    each parameter's convergence is tested on that window (:func:`trajectory_converged`): one still
    drifting gets ``result.converged[name] = False`` and a
    :class:`~hyde_bsdf.inverse._common.NotConvergedWarning` (once; also in ``result.warnings``).
    ``prefix`` picks the BSDF when the scene has several (see :func:`parameter_keys`).
    ``progress``: a callback ``progress(message)`` per iteration; True for ``[invert]`` lines on
    stderr, False for none (:mod:`hyde_bsdf.progress`).
    """
    import drjit as dr
    import mitsuba as mi

    o = InversionOptions.of(options, settings, "invert")
    iterations, lr, spp, seed = o.iterations, o.lr, o.spp, o.seed
    progress = as_callback(progress, "[invert]")
    fit = _check_invert_args(fit, start, iterations)
    params = mi.traverse(scene)
    keys = parameter_keys(params, PARAMETERS, prefix)
    fixed = {p: float(start[p]) for p in PARAMETERS if p not in fit}
    _set(params, keys, {**fixed, **{p: float(start[p]) for p in fit}}, bsdf)
    adam = _log_adam(start, fit, lr, iterations, o.average_last)
    step = _loss_step(params, loss_fn, channel_names(scene), int(spp), o.freeze)
    history = []
    t0 = time.perf_counter()
    t_first = None
    for it in range(iterations):
        t_it = time.perf_counter()
        values = adam.values()
        _apply_values(values, params, keys, bsdf)
        seed_it = dr.opaque(mi.UInt32, int(seed) + 1 + it) if o.freeze else int(seed) + 1 + it
        row = _history_row(step(scene, values, seed_it, loss_fn.tensors), values, fit, it)
        row.update(fixed)
        adam.step(it, values)
        t_first = record_iteration(row, history, t0, t_it, t_first)
        if progress:
            progress(f"it {it + 1:4d}/{iterations}  loss {row['loss']:.3e}  " +
                     "  ".join(f"{p}={row[p]:.4f}" for p in fit) + f"  ({row['seconds']:.1f} s)")
    return _inversion_result(history, fit, fixed, start, truth, loss_fn, o.average_last, t_first)


#: relative drift below which an averaged trajectory counts as settled whatever its scatter
DRIFT_FLOOR = 1e-3


def trajectory_converged(values, name: str = "parameter") -> tuple:
    """(converged, message) of one parameter's iterates over the averaging window: the mean of the
    window's second half against its first half.  A parameter that still moves has a drift larger
    than the window's scatter (a pure linear trend: 1.7 x the standard deviation; jitter around a
    level: ~0.45 x for 20 iterates) -- then, if the drift also exceeds :data:`DRIFT_FLOOR` of the
    value, it has not converged and the averaged value is not a result (message says so; '' else)."""
    v = np.asarray(values, np.float64)
    if v.size < 4:
        return False, (f"{name}: {v.size} iterates averaged, too few to test convergence; "
                       "run more iterations")
    half = v.size // 2
    drift = abs(float(np.mean(v[half:]) - np.mean(v[:half])))
    level = max(abs(float(np.mean(v))), 1e-12)
    if drift <= float(np.std(v)) or drift <= DRIFT_FLOOR * level:
        return True, ""
    return False, (f"{name} has not converged: it moved by {100 * drift / level:.2g} % between the halves of the "
                   f"last {v.size} iterations (more than their scatter); run more iterations or a larger lr")


def loss_and_gradient(scene, loss_fn: StokesLoss, values: dict, *, spp: int, seed: int,
                      seed_grad: int | None = None, bsdf: str = "hyde") -> tuple[float, dict]:
    """The loss at ``values`` and its AD gradient with respect to each of them.

    ``mi.render`` differentiates in a second pass whose samples come from ``seed_grad``;
    by default (None) Mitsuba derives a decorrelated one from ``seed`` (what the
    optimization uses: the gradient is then that of (E[image] - reference)^2, without
    the noise-variance term).  ``seed_grad=seed`` (seed >= 1) makes the gradient pass
    reuse the primal samples: the gradient of exactly the loss that a finite
    difference with that seed sees (computed by tracing the integrator's primal render
    with AD on, as ``mi.render`` refuses equal seeds).
    """
    import drjit as dr
    import mitsuba as mi

    params = mi.traverse(scene)
    keys = parameter_keys(params, tuple(values))
    latent = {}
    for p, v in values.items():
        latent[p] = mi.Float(float(v))
        dr.enable_grad(latent[p])
        params[keys[p]] = latent[p] * SQRT2 if (p == "rms_slope" and bsdf == "roughconductor") else latent[p]
    params.update()
    if seed_grad is not None and int(seed_grad) == int(seed):
        # mi.render refuses equal seeds; the integrator's own render, traced with AD on,
        # differentiates its primal samples directly (fine for small images)
        # (evaluated loops: reverse-mode AD cannot go through the path tracer's symbolic loop)
        with dr.scoped_set_flag(dr.JitFlag.SymbolicLoops, False):
            img = scene.integrator().render(scene, scene.sensors()[0], seed=int(seed), spp=int(spp),
                                            develop=True, evaluate=False)
            loss = loss_fn(stokes_images(img, channel_names(scene)))
            dr.backward(loss)
    else:
        img = mi.render(scene, params, spp=int(spp), seed=int(seed),
                        seed_grad=0 if seed_grad is None else int(seed_grad))
        loss = loss_fn(stokes_images(img, channel_names(scene)))
        dr.backward(loss)
    grads = {p: float(np.asarray(dr.grad(latent[p])).ravel()[0]) for p in values}
    return float(np.asarray(loss).ravel()[0]), grads


def finite_difference_gradient(scene, loss_fn: StokesLoss, values: dict, name: str, *, rel_step: float,
                               spp: int, seed: int, bsdf: str = "hyde") -> float:
    """Central difference dL/d(name) at ``values`` (same seed for both renders), loss in float64."""
    import mitsuba as mi

    h = rel_step * abs(values[name])
    out = []
    for sign in (+1, -1):
        v = dict(values)
        v[name] = values[name] + sign * h
        params = mi.traverse(scene)
        _set(params, parameter_keys(params, tuple(v)), v, bsdf)
        img = mi.render(scene, spp=int(spp), seed=int(seed))
        S = np.array([np.asarray(s, dtype=np.float64) for s in stokes_images(img, channel_names(scene))])
        out.append(loss_fn.numpy(S))
    return (out[0] - out[1]) / (2 * h)


