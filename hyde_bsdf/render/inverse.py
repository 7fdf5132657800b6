"""Differentiable inverse rendering of roughness and index (scalars or texture maps) from Stokes images.

A reference Stokes image of a scene with the ``hyde`` BSDF is matched by a
rendering whose BSDF parameters (``rms_slope``, ``eta``, ``k``; any subset) are
optimized with Mitsuba's ``mi.ad.Adam`` through the ``stokes`` integrator around
``path`` (``prb`` inside ``stokes`` gives the same gradients, bare ``prb`` fails in
polarized variants; ``path`` differentiates through ``mi.render(scene, params, spp=..., seed=...)`` and
``dr.backward``) in ``llvm_ad_spectral_polarized``.

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

Parameters are optimized as their logarithms (so they stay positive and one
learning rate fits all), clamped to the plugin's accepted range, with the
learning rate decaying geometrically over the last quarter.  Each iteration renders
with a new seed (``seed + 1 + iteration``); the reference uses ``seed`` and
``spp_ref`` samples.

Index convention: the plugin's ``eta``, ``k`` are Mitsuba's n + ik; the paper's
eta = n - jk describes the same material with the same numbers.

Texture-valued parameters (SVBRDF, :func:`invert_maps`): a scene whose BSDF takes
``<texture name="alpha" type="bitmap">`` (Beckmann alpha; hyde and roughconductor alike,
key ``...bsdf.alpha.data``), ``rms_slope`` (``rms_slope.data``) or index textures
(``eta.data``, ``k.data``; constants ``eta.value``/``k.value`` are fitted as one number) is
matched to one or more reference Stokes images (:class:`Observation`: scene, sensor, reference,
mask, weight; several views and lights), per texel, with Adam on log(value), the same Stokes loss
per image and an optional smoothness regulariser (:func:`smoothness`, weight lambda documented
there).  :func:`texel_coverage` finds the texels the images see (a UV-coverage pass), over which
errors are reported.  The validation (validation/svbrdf_inverse.py) and the benchmark
(benchmarks/bench_inverse.py) use :data:`MAP_VARIANT` = ``llvm_ad_mono_polarized`` and
:func:`plane_scene_dict` (a textured plane, 3 views in one ``batch`` sensor, one point light per
scene).  Per-texel gradients: the rendering depends on exactly the texels the coverage pass finds
(tests/test_inverse_maps.py: dL/dalpha != 0 there and only there).

Command line (errors: one line on stderr, exit 2; Ctrl-C: exit 130; progress per iteration on
stderr; output paths and memory checked before any rendering; outputs written atomically)::

    hyde-bsdf invert [--scene SCENE.xml [--target PREFIX] | (built-in sphere)] [--truth rms_slope=0.3,eta=1.5,k=3]
                     [--reference REF.exr] [--start rms_slope=0.6,eta=3,k=6]
                     [--fit rms_slope,eta,k] [--loss stokes|s0] [--iterations 200]
                     [--spp 16] [--spp-ref 512] [--res 64] [--lr 0.05] [--seed 0] [-o OUTDIR]

writes OUTDIR/invert_history.csv and OUTDIR/invert.png (loss and parameter trajectories).
Texture mode::

    hyde-bsdf invert --maps [--scene S1.xml --reference R1.exr [--mask M1.png] ...
                     | (built-in plane, 3 views x 2 lights, truth map of --map-size 32)]
                     [--fit alpha[,eta,k]] [--start alpha=0.3] [--regularizer tv|l2 --weight 0.1]
                     [--iterations 100] [--spp 4] [--spp-ref 64] [--res 80] [--sensor 0] [-o OUTDIR]

writes OUTDIR/invert_maps_history.csv, OUTDIR/NAME.npy and NAME.exr per fitted map (rows along
v; load the EXR as a ``bitmap`` texture with ``raw`` true) and OUTDIR/invert_maps.png.
"""
from __future__ import annotations

import argparse
import csv
import gc
import math
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from hyde_bsdf.atomic import atomic_open, atomic_path, check_output_path

__all__ = ["VARIANT", "PARAMETERS", "TRUTH", "START", "prepare", "scene_dict", "load_scene",
           "parameter_keys", "stokes_images", "interior_mask", "StokesLoss", "render_reference",
           "InversionResult", "invert", "loss_and_gradient", "finite_difference_gradient",
           "plot_history", "write_history", "MAP_PARAMETERS", "MAP_VARIANT", "map_keys", "render_stokes",
           "render_stokes_np", "Observation", "texel_coverage", "smoothness", "MapInversionResult",
           "invert_maps", "example_maps", "plane_scene_dict", "cli_main"]

VARIANT = "llvm_ad_spectral_polarized"
#: optimizable BSDF parameters (the plugin's names)
PARAMETERS = ("rms_slope", "eta", "k")
#: ground truth and a start far from it used by the scripts and the CLI by default
TRUTH = {"rms_slope": 0.3, "eta": 1.5, "k": 3.0}
START = {"rms_slope": 0.6, "eta": 3.0, "k": 6.0}
#: the plugin's DHR texture range for rms_slope (diffuse on); eta, k kept in a sane box
RANGES = {"rms_slope": (0.011, 2.9), "eta": (0.02, 50.0), "k": (0.0, 50.0)}
#: luminance weights of linear sRGB (the film's R, G, B)
Y_WEIGHTS = (0.2126, 0.7152, 0.0722)
SQRT2 = math.sqrt(2.0)


def _first_line(exc) -> str:
    text = str(exc).strip().splitlines()
    return text[0][:200] if text else type(exc).__name__


def _log(msg, end="\n"):
    print(f"[invert] {msg}", file=sys.stderr, end=end, flush=True)


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
    """The inverse-rendering scene (as scenes/inverse.xml) as a ``mi.load_dict`` dict.

    ``lighting="points"``: two point lights (front and back; facet angles beta ~ 10-70 deg
    over the image, as scenes/inverse.xml).  ``lighting="directional"``: one distant light
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
        raise ValueError(f"bsdf must be 'hyde' or 'roughconductor', got {bsdf!r}")
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
        raise ValueError(f"lighting must be 'points' or 'directional', got {lighting!r}")
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
            raise ValueError(f"parameter names must be from {PARAMETERS}, got {name!r}")
        out[name] = _unique_key(params, name, [suffix[name]], prefix)
    return out


def _unique_key(params, name, suffix_groups, prefix):
    """The one traverse key ending in a suffix of the first group that matches any key (under
    ``prefix`` if given); ValueError naming ``name``, the suffixes and the keys found otherwise."""
    found = []
    for group in suffix_groups:
        found = [key for key in params.keys() if key.endswith(group)
                 and (prefix is None or key.startswith(prefix + "."))]
        if found:
            break
    if len(found) != 1:
        suffixes = [s for group in suffix_groups for s in group]
        raise ValueError(f"need exactly one BSDF parameter for {name!r} "
                         f"(keys ending in {' or '.join(suffixes)}"
                         f"{'' if prefix is None else ' under ' + repr(prefix)}); found {found}"
                         f"{'; name the BSDF with prefix= (CLI: --target)' if len(found) > 1 else ''}")
    return found[0]


def stokes_images(img, channel_names):
    """Luminance S0..S3 images (4 tensors of shape (H, W), differentiable) of a ``stokes`` render."""
    index = {n: i for i, n in enumerate(channel_names)}
    out = []
    for s in ("S0", "S1", "S2", "S3"):
        out.append(sum(w * img[:, :, index[f"{s}.{c}"]] for c, w in zip("RGB", Y_WEIGHTS)))
    return out


def channel_names(scene):
    """The film's channel names (after a first render)."""
    return [f.name for f in scene.sensors()[0].film().bitmap().struct_()]


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


class StokesLoss:
    """The loss of the module docstring against reference luminance Stokes images ``ref`` (4, H, W)."""

    def __init__(self, ref, mask=None, components: str = "stokes"):
        import mitsuba as mi

        if components not in ("stokes", "s0"):
            raise ValueError(f"components must be 'stokes' or 's0', got {components!r}")
        ref = np.asarray(ref, dtype=np.float64)
        if mask is None:
            mask = interior_mask(ref[0])
        if not mask.any():
            raise ValueError("the reference image has no lit interior pixel: nothing to fit")
        self.components = components
        self.mask_np = mask
        m = mask.astype(np.float64)
        self.norm0 = float((m * ref[0] ** 2).mean())
        self.normp = float((m * (ref[1:] ** 2).sum(0)).mean())
        if self.normp <= 0 and components == "stokes":
            raise ValueError("the reference has no polarization (S1 = S2 = S3 = 0): use components='s0'")
        self.ref = [mi.TensorXf(r.astype(np.float32)) for r in ref]
        self.mask = mi.TensorXf(m.astype(np.float32))
        self.ref_np = ref

    def __call__(self, S, tensors=None):
        """Differentiable loss of luminance Stokes images ``S`` (list of 4 tensors).

        ``tensors``: this loss's own (reference list, mask) (:attr:`tensors`) passed in explicitly,
        as a ``dr.freeze`` function needs every array it reads among its inputs.
        """
        import drjit as dr

        ref, mask = self.tensors if tensors is None else tensors
        loss = dr.mean(mask * dr.square(S[0] - ref[0]), axis=None) / self.norm0
        if self.components == "stokes":
            pol = sum(dr.square(S[c] - ref[c]) for c in (1, 2, 3))
            loss = loss + dr.mean(mask * pol, axis=None) / self.normp
        return loss

    @property
    def tensors(self):
        """(reference tensors S0..S3, mask tensor) as Dr.Jit arrays."""
        return self.ref, self.mask

    def numpy(self, S) -> float:
        """The same loss in float64 from NumPy images (4, H, W) (finite differences)."""
        S = np.asarray(S, dtype=np.float64)
        m = self.mask_np.astype(np.float64)
        loss = (m * (S[0] - self.ref_np[0]) ** 2).mean() / self.norm0
        if self.components == "stokes":
            loss += (m * ((S[1:] - self.ref_np[1:]) ** 2).sum(0)).mean() / self.normp
        return float(loss)


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

    def relative_errors(self) -> dict:
        if not self.truth:
            return {}
        return {n: (self.final[n] - self.truth[n]) / self.truth[n] for n in self.fitted}


def invert(scene, loss_fn: StokesLoss, start: dict, *, fit=PARAMETERS, iterations: int = 200,
           lr: float = 0.05, spp: int = 16, seed: int = 0, truth: dict | None = None,
           bsdf: str = "hyde", progress: bool = True, average_last: int = 20,
           prefix: str | None = None) -> InversionResult:
    """Optimize the BSDF parameters ``fit`` of ``scene`` to minimize ``loss_fn``.

    ``start`` gives every parameter's start value (the unfitted ones stay there).
    Adam on log(parameter), lr decaying by 5 % per iteration over the last quarter;
    iteration i renders ``spp`` samples with seed ``seed + 1 + i``.  The final value
    is the mean of the parameters over the last ``average_last`` iterations
    (Polyak averaging: it cancels the Monte-Carlo jitter of single steps).
    ``prefix`` picks the BSDF when the scene has several (see :func:`parameter_keys`).
    """
    import drjit as dr
    import mitsuba as mi

    fit = tuple(p for p in PARAMETERS if p in fit)
    if not fit:
        raise ValueError(f"fit must name at least one of {PARAMETERS}")
    missing = [p for p in PARAMETERS if p not in start]
    if missing:
        raise ValueError(f"start must give a value for every parameter; missing {missing}")
    if not (isinstance(iterations, int) and iterations >= 1):
        raise ValueError(f"iterations must be an integer >= 1, got {iterations!r}")
    params = mi.traverse(scene)
    keys = parameter_keys(params, PARAMETERS, prefix)
    fixed = {p: float(start[p]) for p in PARAMETERS if p not in fit}
    _set(params, keys, {**fixed, **{p: float(start[p]) for p in fit}}, bsdf)
    opt = mi.ad.Adam(lr=lr)
    for p in fit:
        lo, hi = RANGES[p]
        opt[p] = mi.Float(math.log(min(max(float(start[p]), max(lo, 1e-6)), hi)))
    names = None
    history = []
    t0 = time.perf_counter()
    t_first = None
    rate = lr
    for it in range(iterations):
        t_it = time.perf_counter()
        values = {}
        for p in fit:
            lo, hi = RANGES[p]
            # keep the latent inside the accepted range (the plugin refuses rms_slope outside its DHR table)
            opt[p] = dr.clip(opt[p], math.log(max(lo, 1e-6)), math.log(hi))
            values[p] = dr.exp(opt[p])
            if p == "rms_slope" and bsdf == "roughconductor":
                params[keys[p]] = values[p] * SQRT2
            else:
                params[keys[p]] = values[p]
        params.update()
        img = mi.render(scene, params, spp=int(spp), seed=int(seed) + 1 + it)
        if names is None:
            names = channel_names(scene)
        loss = loss_fn(stokes_images(img, names))
        dr.backward(loss)
        row = {"iteration": it, "loss": float(np.asarray(loss).ravel()[0])}
        row.update({p: float(np.asarray(values[p]).ravel()[0]) for p in fit})
        if not math.isfinite(row["loss"]):   # never hand back a NaN trajectory silently
            raise FloatingPointError(f"the loss became {row['loss']} at iteration {it} with "
                                     + ", ".join(f"{p}={row[p]:.6g}" for p in fit))
        row.update(fixed)
        opt.step()
        if it >= iterations - iterations // 4:
            rate *= 0.95
            opt.set_learning_rate(rate)
        dt = time.perf_counter() - t_it
        if t_first is None:
            t_first = dt
        row["seconds"] = time.perf_counter() - t0
        history.append(row)
        if progress:
            _log(f"it {it + 1:4d}/{iterations}  loss {row['loss']:.3e}  " +
                 "  ".join(f"{p}={row[p]:.4f}" for p in fit) + f"  ({row['seconds']:.1f} s)")
    tail = history[-min(average_last, len(history)):]
    final = {p: float(np.mean([r[p] for r in tail])) for p in fit}
    final.update(fixed)
    per_it = ((history[-1]["seconds"] - history[0]["seconds"]) / (len(history) - 1)
              if len(history) > 1 else float("nan"))
    return InversionResult(fitted=fit, start=dict(start), final=final, truth=truth,
                           components=loss_fn.components, history=history,
                           seconds_per_iteration=per_it, first_iteration_seconds=t_first)


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


def write_history(result: InversionResult, path) -> Path:
    """CSV: one row per iteration (iteration, loss, seconds, parameters)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    cols = ["iteration", "loss", "seconds"] + list(PARAMETERS)
    with atomic_open(path, "w", newline="") as fh:
        w = csv.writer(fh)
        fh.write(f"# loss={result.components}; truth={result.truth}; start={result.start}; "
                 f"final (mean of the last iterations)={result.final}\n")
        w.writerow(cols)
        for r in result.history:
            w.writerow([r["iteration"], f"{r['loss']:.6e}", f"{r['seconds']:.3f}"] +
                       [f"{r[p]:.6g}" for p in PARAMETERS])
    return path


def plot_history(results: dict, path, title: str = "") -> Path:
    """Loss and parameter trajectories (relative to the truth when known) of one or more runs."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 1 + len(PARAMETERS), figsize=(4.2 * (1 + len(PARAMETERS)), 3.4))
    for c, (label, res) in enumerate(results.items()):
        it = [r["iteration"] for r in res.history]
        axes[0].semilogy(it, [r["loss"] for r in res.history], f"C{c}-", lw=1, label=label)
        for a, p in zip(axes[1:], PARAMETERS):
            a.plot(it, [r[p] for r in res.history], f"C{c}-", lw=1.2, label=label)
            if res.truth:
                a.axhline(res.truth[p], color="k", ls="--", lw=0.8)
    axes[0].set_title("loss (each run's own)")
    axes[0].set_xlabel("iteration")
    axes[0].legend(fontsize=7)
    for a, p in zip(axes[1:], PARAMETERS):
        a.set_title(f"{p} (dashed: truth)")
        a.set_xlabel("iteration")
        a.grid(alpha=0.3)
    if title:
        fig.suptitle(title, fontsize=9)
    fig.tight_layout()
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    with atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=110, format="png")
    plt.close(fig)
    return path


# ---------------------------------------------------------------------------
# texture-valued (SVBRDF) inversion: roughness map, optionally index maps, from several images

#: texture-valued parameters: name -> (traverse-key suffixes, accepted range).  ``alpha`` is the
#: Beckmann alpha (roughconductor's meaning and key; hyde's ``alpha`` texture), ``rms_slope`` hyde's
#: own roughness texture (alpha = sqrt(2) rms_slope), ``eta``, ``k`` the index (Mitsuba's n + ik).
MAP_PARAMETERS = {
    "alpha": ((".alpha.data", ".alpha.value"), (SQRT2 * 0.011, SQRT2 * 2.9)),
    "rms_slope": ((".rms_slope.data", ".rms_slope.value", ".rms_slope"), RANGES["rms_slope"]),
    "eta": ((".eta.data", ".eta.value"), RANGES["eta"]),
    "k": ((".k.data", ".k.value"), (1e-4, RANGES["k"][1])),
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
            raise ValueError(f"parameter names must be from {tuple(MAP_PARAMETERS)}, got {name!r}")
        # suffixes tried in order: the texture's data first, then a constant's value
        out[name] = _unique_key(params, name, [(s,) for s in MAP_PARAMETERS[name][0]], prefix)
    return out


def film_channels(scene, sensor: int = 0) -> list:
    """The channel names of a sensor's film under the scene's integrator (R, G, B[, A], S0.R, ...)."""
    film = scene.sensors()[int(sensor)].film()
    base = ["Y"] if film.base_channels_count() == 1 else ["R", "G", "B", "A"][:film.base_channels_count()]
    return base + list(scene.integrator().aov_names())


def render_stokes(scene, sensor: int = 0, spp: int = 16, seed: int = 0, params=None, names=None) -> list:
    """Luminance S0..S3 tensors (H, W) of one sensor's render (differentiable when ``params`` given).

    ``names``: the film's channel names (:func:`film_channels`), given by a caller that renders
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
    share of the data loss.  Several observations may share a scene (one per sensor) or use
    different scenes (e.g. one per light: one light per render avoids the light-selection noise
    of a scene with several lights); the fitted textures are written into every scene.
    """

    scene: object
    reference: np.ndarray
    sensor: int = 0
    mask: np.ndarray | None = None
    weight: float = 1.0


def texel_coverage(obs: Observation, shape, prefix: str | None = None, sub: int = 4) -> np.ndarray:
    """Samples per texel of a (rows, columns) map on the target shape that ``obs``'s masked pixels see.

    Casts ``sub`` x ``sub`` camera rays per pixel of the loss mask (what the loss uses), keeps those
    whose first hit is the shape carrying the target BSDF (``prefix``, default: the one shape whose
    BSDF has a texture parameter) and bins their UV into texels as the nearest-neighbour bitmap
    lookup does (column = floor(u W), row = floor(v H); ``to_uv`` is assumed identity).
    Returns counts (rows, columns); a texel with 0 is never seen, so it carries no information.
    """
    import drjit as dr
    import mitsuba as mi

    scene = obs.scene
    sensor = scene.sensors()[int(obs.sensor)]
    W, H = sensor.film().crop_size()
    mask = _obs_mask(obs)
    ys, xs = np.nonzero(mask)
    o = (np.arange(sub) + 0.5) / sub
    ox, oy = np.meshgrid(o, o)
    px = (xs[:, None] + ox.ravel()[None, :]).ravel() / W
    py = (ys[:, None] + oy.ravel()[None, :]).ravel() / H
    target = _target_shape(scene, prefix)
    # the film positions go in as Python lists: Dr.Jit then owns copies.  Arrays made straight from
    # NumPy memory stay referenced by the sensor's state and are released later through a host
    # callback, which a later dr.freeze recording cannot hold (Dr.Jit aborts the process)
    ray, _ = sensor.sample_ray(mi.Float(0.0), mi.Float(0.5), mi.Point2f(mi.Float(px.tolist()), mi.Float(py.tolist())),
                               mi.Point2f(0.5, 0.5))
    si = scene.ray_intersect(ray)
    hit = np.array(si.is_valid() & (si.shape == mi.ShapePtr(target)), dtype=bool)
    uv = np.array([np.array(si.uv.x, dtype=np.float64), np.array(si.uv.y, dtype=np.float64)])
    rows, cols = shape
    c = np.clip(np.floor(uv[0][hit] * cols).astype(int), 0, cols - 1)
    r = np.clip(np.floor(uv[1][hit] * rows).astype(int), 0, rows - 1)
    counts = np.zeros((rows, cols), int)
    np.add.at(counts, (r, c), 1)
    return counts


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
        raise ValueError(f"need exactly one shape carrying the textured BSDF"
                         f"{'' if prefix is None else ' ' + repr(prefix)}; found "
                         f"{[s.id() for s in found]} (name it with prefix='ID.bsdf')")
    return found[0]


def _obs_mask(obs: Observation) -> np.ndarray:
    ref = np.asarray(obs.reference, dtype=np.float64)
    mask = interior_mask(ref[0]) if obs.mask is None else np.asarray(obs.mask, bool)
    if mask.shape != ref.shape[1:]:
        raise ValueError(f"mask shape {mask.shape} differs from the reference's {ref.shape[1:]}")
    return mask


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
        raise ValueError(f"regularizer must be 'tv' or 'l2', got {kind!r}")
    total, n = 0.0, 0
    for d, count in terms:
        pen = dr.sqrt(dr.square(d) + eps * eps) - eps if kind == "tv" else dr.square(d)
        total = total + dr.sum(pen, axis=None)
        n += count
    return total / max(n, 1)


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
                     res: int = 96, spp: int = 4, diffuse: str = "paper", views=VIEW_AZIMUTHS) -> dict:
    """A 2 x 2 plane (shape id ``plane``, UV = (x + 1, y + 1) / 2) with the roughness map ``alpha``
    (Beckmann alpha, rows along v, nearest-neighbour lookup) and a constant index, seen by
    ``len(views)`` cameras side by side in one ``batch`` sensor (film ``len(views) * res`` x ``res``),
    lit by point light ``LIGHTS[light]``.  ``bsdf``: ``hyde`` or ``roughconductor`` (Beckmann,
    the same alpha, eta, k).  Direct light only (``stokes`` around ``path``, max_depth 2)."""
    import mitsuba as mi

    tex = {"type": "bitmap", "bitmap": mi.Bitmap(np.asarray(alpha, np.float32)[..., None]), "raw": True,
           "filter_type": "nearest"}
    if bsdf == "hyde":
        material = {"type": "hyde", "alpha": tex, "eta": float(eta), "k": float(k), "diffuse": diffuse}
    elif bsdf == "roughconductor":
        material = {"type": "roughconductor", "distribution": "beckmann", "alpha": tex,
                    "eta": float(eta), "k": float(k)}
    else:
        raise ValueError(f"bsdf must be 'hyde' or 'roughconductor', got {bsdf!r}")
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


# ---------------------------------------------------------------------------
# command line

try:                                           # the package's one user-error type, where present
    from hyde_bsdf.errors import UsageError
except ImportError:                            # pragma: no cover -- older trees
    class UsageError(ValueError):
        """A user mistake (argument, input or output path, scene): one-line message, exit 2."""

#: peak memory of one differentiable render (reverse mode through ``path``): a fixed part plus
#: bytes per sample (measured: 1.4-1.5 kB/sample spectral polarized sphere at 64-128 px, 16 spp;
#: 0.8-1.2 kB mono polarized plane, 3 x 80-160 px, 4 spp; the figure below has a margin)
AD_BYTES_FIXED = 400 * 2**20
AD_BYTES_PER_SAMPLE = 2048
EXIT_USAGE, EXIT_INTERRUPTED = 2, 130


def estimate_memory(width: int, height: int, spp: int) -> int:
    """Estimated peak memory (bytes) of one optimisation step on a ``width`` x ``height`` film."""
    return AD_BYTES_FIXED + AD_BYTES_PER_SAMPLE * int(width) * int(height) * int(spp)


def _mem_available():
    try:
        with open("/proc/meminfo") as fh:
            for line in fh:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        pass
    return None


def check_memory(width: int, height: int, spp: int, hint: str) -> int:
    """UsageError when :func:`estimate_memory` exceeds the available memory; returns the estimate."""
    need, avail = estimate_memory(width, height, spp), _mem_available()
    if avail is not None and need > avail:
        raise UsageError(f"one optimisation step on the {width}x{height} film at {spp} spp needs about "
                         f"{need / 2**30:.1f} GiB ({AD_BYTES_PER_SAMPLE} B per sample + "
                         f"{AD_BYTES_FIXED // 2**20} MiB), but only {avail / 2**30:.1f} GiB is available; "
                         f"lower {hint}")
    return need


def _one_line(exc) -> str:
    return " | ".join(p.strip() for p in str(exc).strip().splitlines() if p.strip())


def _parse_values(text, what, names=PARAMETERS, ranges=None):
    ranges = ranges or RANGES
    out = {}
    for item in filter(None, (s.strip() for s in text.split(","))):
        if "=" not in item:
            raise UsageError(f"{what}: expected name=value pairs like "
                             f"{','.join(f'{n}=0.3' for n in names[:2])}; got {item!r}")
        name, value = (s.strip() for s in item.split("=", 1))
        if name not in names:
            raise UsageError(f"{what}: unknown parameter {name!r}; use {', '.join(names)}")
        try:
            v = float(value)
        except ValueError:
            raise UsageError(f"{what}: {name}={value!r} is not a number") from None
        lo, hi = ranges[name]
        if not (math.isfinite(v) and lo <= v <= hi):
            raise UsageError(f"{what}: {name}={v:g} is outside the accepted range [{lo:g}, {hi:g}]")
        out[name] = v
    return out


class _Parser(argparse.ArgumentParser):
    """argparse, but a bad argument is one UsageError line (not usage text + exit)."""

    def error(self, message):
        raise UsageError(message)


def build_parser():
    ap = _Parser(
        prog="hyde-bsdf invert",
        description="Recover the hyde BSDF's roughness and index from Stokes images by differentiable "
                    "rendering.  Scalar mode (default): rms_slope, eta, k (Mitsuba n + ik; the paper's "
                    "eta = n - jk, same numbers) from one image (llvm_ad_spectral_polarized).  --maps: a "
                    "texture-valued roughness (alpha or rms_slope bitmap), optionally index maps, from "
                    "one or more images (llvm_ad_mono_polarized).")
    ap.add_argument("--maps", action="store_true", help="texture-valued mode: fit per-texel maps")
    ap.add_argument("--scene", action="append", default=None,
                    help="Mitsuba XML scene holding the BSDF (repeat for several scenes, e.g. one per light; "
                         "default: the built-in sphere (scalar) or textured plane, 3 views x 2 lights (--maps))")
    ap.add_argument("--reference", action="append", default=None,
                    help="reference Stokes EXR of the matching --scene (hyde-bsdf render output; same film "
                         "size); default: render one at --truth (built-in truth map with --maps)")
    ap.add_argument("--mask", action="append", default=None,
                    help="--maps: PNG or .npy of the pixels to use for the matching --reference (non-zero = use)")
    ap.add_argument("--sensor", type=int, default=0, help="index of the sensor of each --scene (default 0)")
    ap.add_argument("--target", default=None, help="key prefix of the BSDF to recover when the scene has "
                    "several, e.g. sphere.bsdf (mi.traverse names)")
    ap.add_argument("--truth", default=None, help="scalar mode: parameters of the reference rendering "
                    "(default rms_slope=0.3,eta=1.5,k=3); errors are reported against them")
    ap.add_argument("--start", default=None, help="start values, name=value,... (default rms_slope=0.6,"
                    "eta=3,k=6; --maps: alpha=0.3, a constant map)")
    ap.add_argument("--fit", default=None, help="parameters to optimise (default rms_slope,eta,k; --maps: alpha; "
                    "--maps accepts alpha|rms_slope, eta, k)")
    ap.add_argument("--loss", default="stokes", choices=("stokes", "s0"),
                    help="stokes: all four Stokes components; s0: intensity only")
    ap.add_argument("--iterations", type=int, default=None, help="Adam iterations (default 200; --maps 100)")
    ap.add_argument("--spp", type=int, default=None, help="samples per pixel and iteration (default 16; --maps 4)")
    ap.add_argument("--spp-ref", type=int, default=None, help="samples per pixel of a rendered reference "
                    "(default 512; --maps 64)")
    ap.add_argument("--res", type=int, default=None, help="image size of the built-in scene (default 64; "
                    "--maps: 80 per view)")
    ap.add_argument("--map-size", type=int, default=32, help="--maps, built-in scene: texels per side of the "
                    "truth map (default 32)")
    ap.add_argument("--lr", type=float, default=0.05, help="Adam learning rate (on log parameters)")
    ap.add_argument("--regularizer", default=None, choices=("tv", "l2"),
                    help="--maps: smoothness term on each fitted map (total variation or squared gradient)")
    ap.add_argument("--weight", type=float, default=0.0, help="--maps: regulariser weight lambda (loss units "
                    "per map unit (tv) or squared map unit (l2); 0.1 mild, >= 1 flattens; default 0)")
    ap.add_argument("--seed", type=int, default=0, help="random seed (integer >= 0)")
    ap.add_argument("-o", "--output", default="out/invert", help="output folder (default out/invert)")
    return ap


def _check_args(args):
    maps = args.maps
    d = {"iterations": 100 if maps else 200, "spp": 4 if maps else 16, "spp_ref": 64 if maps else 512,
         "res": 80 if maps else 64}
    for k, v in d.items():
        if getattr(args, k) is None:
            setattr(args, k, v)
    for flag, v, lo in (("--iterations", args.iterations, 1), ("--spp", args.spp, 1),
                        ("--spp-ref", args.spp_ref, 1), ("--res", args.res, 1), ("--seed", args.seed, 0),
                        ("--sensor", args.sensor, 0), ("--map-size", args.map_size, 2)):
        if v < lo:
            raise UsageError(f"{flag} must be an integer >= {lo}, got {v}")
    if args.seed + (args.iterations + 1) * 8 >= 2**31:
        raise UsageError(f"--seed must be < {2**31 - (args.iterations + 1) * 8} (seeds of the later iterations "
                         f"are --seed + 1 + iteration x images), got {args.seed}")
    if not (math.isfinite(args.lr) and args.lr > 0):
        raise UsageError(f"--lr must be a finite number > 0, got {args.lr}")
    if not (math.isfinite(args.weight) and args.weight >= 0):
        raise UsageError(f"--weight must be a finite number >= 0, got {args.weight}")
    if not maps and (args.regularizer or args.weight or args.mask):
        raise UsageError("--regularizer, --weight and --mask need --maps (they act on texture maps)")
    scenes, refs, masks = args.scene or [], args.reference or [], args.mask or []
    if refs and len(refs) != max(1, len(scenes)):
        raise UsageError(f"give one --reference per --scene: {len(scenes)} --scene, {len(refs)} --reference")
    if maps and scenes and not refs:
        raise UsageError("--maps with --scene needs a --reference per scene (the truth maps of a user scene "
                         "are unknown)")
    if not maps and len(scenes) > 1:
        raise UsageError("scalar mode takes one --scene; several scenes need --maps")
    if masks and len(masks) != len(refs):
        raise UsageError(f"give one --mask per --reference: {len(refs)} --reference, {len(masks)} --mask")
    for path in scenes + refs + masks:
        if not Path(path).is_file():
            raise UsageError(f"{path!r} is not an existing file")
    if args.truth is not None and refs:
        pass                                   # errors are reported against it
    if maps and args.truth is not None:
        raise UsageError("--truth is for scalar mode; --maps renders its references from the built-in "
                         "truth map or reads --reference")


def _check_out(path):
    """An output file checked writable before any long work (a UsageError naming -o otherwise)."""
    try:
        return check_output_path(path, "-o/--output file")
    except ValueError as exc:
        raise UsageError(_one_line(exc)) from None


def _read_reference(path, width, height, what="--reference"):
    """Luminance Stokes images (4, H, W) of a Stokes EXR, checked against the film size and for NaN."""
    from hyde_bsdf.render.stokes_io import read_stokes_exr

    try:
        st = read_stokes_exr(path)
    except (ValueError, OSError, RuntimeError) as exc:
        raise UsageError(f"{what} {str(path)!r}: {_one_line(exc)}") from None
    ref = np.array([np.asarray(st[s], np.float64) @ np.array(Y_WEIGHTS) for s in ("S0", "S1", "S2", "S3")])
    h, w = ref.shape[1:]
    if (w, h) != (width, height):
        raise UsageError(f"{what} {str(path)!r} is {w}x{h} pixels but the scene's film is {width}x{height}: "
                         f"render the reference with the same scene and film")
    bad = int((~np.isfinite(ref)).any(axis=0).sum())
    if bad:
        raise UsageError(f"{what} {str(path)!r} has {bad} pixel(s) with NaN or infinite Stokes values; "
                         f"the loss needs finite references")
    return ref


def _read_mask(path, shape):
    path = Path(path)
    try:
        if path.suffix.lower() == ".npy":
            m = np.load(path)
        else:
            import matplotlib.image as mpimg

            m = mpimg.imread(str(path))
    except (OSError, ValueError) as exc:
        raise UsageError(f"--mask {str(path)!r}: cannot read it ({_one_line(exc)}); give a PNG or .npy") from None
    m = np.asarray(m)
    if m.ndim == 3:
        m = m[..., :3].max(axis=2)
    if m.shape != tuple(shape):
        raise UsageError(f"--mask {str(path)!r} is {m.shape[1]}x{m.shape[0]} pixels but the film is "
                         f"{shape[1]}x{shape[0]}")
    return m != 0


def _load_user_scene(path):
    try:
        return load_scene(path)
    except (RuntimeError, ValueError) as exc:
        raise UsageError(f"--scene {str(path)!r}: Mitsuba could not load it: {_one_line(exc)[:400]}") from None


def cli_main(argv=None) -> int:
    """``hyde-bsdf invert``: one-line errors (exit 2), Ctrl-C exit 130, progress on stderr."""
    try:
        return _cli(argv)
    except KeyboardInterrupt:
        print("hyde-bsdf invert: interrupted (no output written for this run)", file=sys.stderr)
        return EXIT_INTERRUPTED
    except UsageError as exc:
        print(f"hyde-bsdf invert: error: {_one_line(exc)}", file=sys.stderr)
        return EXIT_USAGE
    except FloatingPointError as exc:
        print(f"hyde-bsdf invert: error: {_one_line(exc)} (try a smaller --lr or more --spp)", file=sys.stderr)
        return 1
    except RuntimeError as exc:
        cause = exc
        while cause is not None:               # Ctrl-C inside mi.render comes back wrapped
            if isinstance(cause, KeyboardInterrupt):
                print("hyde-bsdf invert: interrupted (no output written for this run)", file=sys.stderr)
                return EXIT_INTERRUPTED
            cause = cause.__cause__ or cause.__context__
        raise


def _cli(argv):
    args = build_parser().parse_args(argv)
    _check_args(args)
    if args.maps:
        return _cli_maps(args)
    truth = {**TRUTH, **_parse_values(args.truth or "", "--truth")}
    start = {**START, **_parse_values(args.start or "", "--start")}
    fit = tuple(s.strip() for s in (args.fit or ",".join(PARAMETERS)).split(",") if s.strip())
    bad = [p for p in fit if p not in PARAMETERS]
    if bad or not fit:
        raise UsageError(f"--fit must list parameters from {', '.join(PARAMETERS)}, got {args.fit!r}")
    out = Path(args.output)
    paths = [_check_out(out / name) for name in ("invert_history.csv", "invert.png")]
    try:
        prepare()
    except RuntimeError as exc:
        raise UsageError(_one_line(exc)) from None
    import mitsuba as mi

    scene = (load_scene(None, res=args.res, spp=args.spp) if not args.scene else _load_user_scene(args.scene[0]))
    try:
        parameter_keys(mi.traverse(scene), PARAMETERS, args.target)   # exactly one hyde BSDF, or a clear error
    except ValueError as exc:
        raise UsageError(_one_line(exc)) from None
    W, H = scene.sensors()[0].film().crop_size()
    check_memory(W, H, args.spp, "--spp" + (" or --res" if not args.scene else " or the film's width/height"))
    if args.reference:
        ref = _read_reference(args.reference[0], W, H)
        truth_known = args.truth is not None
    else:
        _log(f"rendering the reference at {truth} ({args.spp_ref} spp)")
        ref = render_reference(scene, truth, args.spp_ref, seed=args.seed, prefix=args.target)
        truth_known = True
    try:
        loss_fn = StokesLoss(ref, components=args.loss)
    except ValueError as exc:
        raise UsageError(f"--reference: {_one_line(exc)}") from None
    res = invert(scene, loss_fn, start, fit=fit, iterations=args.iterations, lr=args.lr, spp=args.spp,
                 seed=args.seed, truth=truth if truth_known else None, prefix=args.target)
    write_history(res, paths[0])
    plot_history({args.loss: res}, paths[1],
                 title=f"hyde-bsdf invert ({args.loss} loss, {args.iterations} it, {args.spp} spp)")
    print(f"loss: {args.loss}; {args.iterations} iterations, {res.seconds_per_iteration:.3f} s/iteration "
          f"(first {res.first_iteration_seconds:.1f} s incl. JIT)")
    for p in PARAMETERS:
        line = f"  {p:9s} start {start[p]:.4g} -> {res.final[p]:.5g}"
        if res.truth and p in res.fitted:
            line += f"   truth {truth[p]:.4g}, error {100 * (res.final[p] / truth[p] - 1):+.2f} %"
        elif p not in res.fitted:
            line += " (fixed)"
        print(line)
    print(f"wrote {paths[0]} and {paths[1]}")
    return 0


def _cli_maps(args):
    names = tuple(MAP_PARAMETERS)
    ranges = {n: MAP_PARAMETERS[n][1] for n in names}
    fit = tuple(s.strip() for s in (args.fit or "alpha").split(",") if s.strip())
    bad = [p for p in fit if p not in names]
    if bad or not fit:
        raise UsageError(f"--fit must list parameters from {', '.join(names)}, got {args.fit!r}")
    if "alpha" in fit and "rms_slope" in fit:
        raise UsageError("--fit: alpha and rms_slope are the same roughness; fit one of them")
    start = {n: 0.3 for n in fit if n in ("alpha", "rms_slope")}
    start.update(_parse_values(args.start or "", "--start", names, ranges))
    missing = [n for n in fit if n not in start]
    if missing:
        raise UsageError(f"--start must give a start value for {', '.join(missing)} (e.g. --start "
                         f"{','.join(f'{n}=1.5' for n in missing)})")
    out = Path(args.output)
    outputs = {"history": "invert_maps_history.csv", "png": "invert_maps.png"}
    for n in fit:
        outputs[n + ".npy"] = f"{n}.npy"
        outputs[n + ".exr"] = f"{n}.exr"
    paths = {k: _check_out(out / v) for k, v in outputs.items()}
    try:
        prepare(MAP_VARIANT)
    except RuntimeError as exc:
        raise UsageError(_one_line(exc)) from None
    import mitsuba as mi

    truth = None
    if args.scene:
        scenes = [_load_user_scene(p) for p in args.scene]
    else:
        truth_map = example_maps(args.map_size)
        truth = {"alpha": truth_map} if fit == ("alpha",) else None
        if fit != ("alpha",):
            raise UsageError("the built-in --maps scene has a known index (eta 1.5, k 3) and an alpha map: "
                             "--fit alpha (give --scene/--reference for other fits)")
        scenes = [mi.load_dict(plane_scene_dict(truth_map, light=j, res=args.res, spp=args.spp))
                  for j in range(len(LIGHTS))]
    observations = []
    for i, scene in enumerate(scenes):
        if args.sensor >= len(scene.sensors()):
            raise UsageError(f"--sensor {args.sensor}: scene {i} has {len(scene.sensors())} sensor(s)")
        try:
            map_keys(mi.traverse(scene), fit, args.target)
        except ValueError as exc:
            raise UsageError(f"scene {i}: {_one_line(exc)}") from None
        W, H = scene.sensors()[args.sensor].film().crop_size()
        check_memory(W, H, args.spp, "--spp" + (" or --res" if not args.scene else " or the film's width/height"))
        if args.reference:
            ref = _read_reference(args.reference[i], W, H)
        else:
            _log(f"rendering reference {i + 1}/{len(scenes)} ({args.spp_ref} spp)")
            ref = render_stokes_np(scene, args.sensor, args.spp_ref, seed=args.seed)
        mask = _read_mask(args.mask[i], (H, W)) if args.mask else None
        observations.append(Observation(scene, ref, sensor=args.sensor, mask=mask))
    try:
        res = invert_maps(observations, start, fit=fit, iterations=args.iterations, lr=args.lr, spp=args.spp,
                          seed=args.seed, components=args.loss, regularizer=args.regularizer, weight=args.weight,
                          truth=truth, prefix=args.target)
    except ValueError as exc:              # the inputs (masks, start shapes) found inconsistent
        raise UsageError(_one_line(exc)) from None
    _write_map_outputs(res, paths, args)
    print(f"loss: {args.loss}; {args.iterations} iterations over {len(observations)} image(s), "
          f"{res.seconds_per_iteration:.3f} s/iteration (first {res.first_iteration_seconds:.1f} s incl. JIT)")
    for n in fit:
        v = np.asarray(res.final[n])
        line = f"  {n:9s} start {start[n]:.4g} -> "
        line += (f"map {v.shape[1]}x{v.shape[0]}, {v.min():.4g}..{v.max():.4g} (median {np.median(v):.4g})"
                 if v.ndim == 2 else f"{float(v):.5g}")
        if truth and n in truth:
            e = res.texel_errors(n)
            line += (f"; per-texel error over the {int(res.seen.sum())} seen texels: median "
                     f"{100 * np.median(e):.2f} %, 90th percentile {100 * np.percentile(e, 90):.2f} %")
        print(line)
    if res.seen is not None:
        print(f"  texels seen by the images: {int(res.seen.sum())} of {res.seen.size}")
    print("wrote " + ", ".join(str(p) for p in paths.values()))
    return 0


def _write_map_outputs(res, paths, args):
    import mitsuba as mi

    with atomic_open(paths["history"], "w", newline="") as fh:
        w = csv.writer(fh)
        cols = ["iteration", "loss", "data_loss", "regularizer", "seconds"]
        extra = [k for k in res.history[0] if k.endswith("_error")]
        w.writerow(cols + extra)
        for h in res.history:
            w.writerow([h["iteration"]] + [f"{h[c]:.6e}" for c in cols[1:4]] + [f"{h['seconds']:.3f}"]
                       + [f"{h[c]:.5f}" for c in extra])
    for n in res.fitted:
        v = np.asarray(res.final[n], np.float32)
        with atomic_path(paths[n + ".npy"]) as tmp:
            with open(tmp, "wb") as fh:
                np.save(fh, v)
        with atomic_path(paths[n + ".exr"]) as tmp:
            mi.Bitmap(v[..., None] if v.ndim == 2 else np.full((1, 1, 1), v, np.float32)).write(str(tmp))
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    maps = [n for n in res.fitted if np.ndim(res.final[n]) == 2]
    cols = 1 + sum(2 if res.truth and n in res.truth else 1 for n in maps)
    fig, axes = plt.subplots(1, max(cols, 2), figsize=(4.2 * max(cols, 2), 3.6), layout="constrained")
    c = 0
    for n in maps:
        im = axes[c].imshow(res.final[n], origin="lower", extent=(0, 1, 0, 1))
        fig.colorbar(im, ax=axes[c], shrink=0.8)
        axes[c].set_title(f"recovered {n}")
        c += 1
        if res.truth and n in res.truth:
            rel = 100 * (res.final[n] / res.truth[n] - 1)
            if res.seen is not None:
                rel = np.where(res.seen, rel, np.nan)
            im = axes[c].imshow(rel, origin="lower", extent=(0, 1, 0, 1), cmap="RdBu_r", vmin=-15, vmax=15)
            fig.colorbar(im, ax=axes[c], shrink=0.8)
            axes[c].set_title(f"{n} / truth - 1 (%)")
            c += 1
    axes[c].semilogy([h["iteration"] for h in res.history], [h["loss"] for h in res.history])
    axes[c].set_xlabel("iteration")
    axes[c].set_title(f"loss ({args.loss})")
    with atomic_path(paths["png"]) as tmp:
        fig.savefig(tmp, dpi=100, format="png")
    plt.close(fig)
