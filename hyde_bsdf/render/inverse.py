"""Differentiable inverse rendering of roughness and index from a Stokes image.

A reference Stokes image of a scene with the ``hyde`` BSDF is matched by a
rendering whose BSDF parameters (``rms_slope``, ``eta``, ``k``; any subset) are
optimized with Mitsuba's ``mi.ad.Adam`` through the ``stokes`` integrator around
``path`` (Mitsuba's ``prb`` integrators refuse polarized variants; ``path``
differentiates through ``mi.render(scene, params, spp=..., seed=...)`` and
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

Command line::

    hyde-bsdf invert [--scene SCENE.xml [--target PREFIX] | (built-in scene)] [--truth rms_slope=0.3,eta=1.5,k=3]
                     [--reference REF.exr] [--start rms_slope=0.6,eta=3,k=6]
                     [--fit rms_slope,eta,k] [--loss stokes|s0] [--iterations 200]
                     [--spp 16] [--spp-ref 512] [--res 64] [--lr 0.05] [--seed 0] [-o OUTDIR]

writes OUTDIR/invert_history.csv and OUTDIR/invert.png (loss and parameter trajectories).
"""
from __future__ import annotations

import argparse
import csv
import math
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

__all__ = ["VARIANT", "PARAMETERS", "TRUTH", "START", "prepare", "scene_dict", "load_scene",
           "parameter_keys", "stokes_images", "interior_mask", "StokesLoss", "render_reference",
           "InversionResult", "invert", "loss_and_gradient", "finite_difference_gradient",
           "plot_history", "write_history", "cli_main"]

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
        found = [key for key in params.keys() if key.endswith(suffix[name])
                 and (prefix is None or key.startswith(prefix + "."))]
        if len(found) != 1:
            raise ValueError(f"need exactly one BSDF parameter for {name!r} "
                             f"(keys ending in {' or '.join(suffix[name])}"
                             f"{'' if prefix is None else ' under ' + repr(prefix)}); found {found}"
                             f"{'; name the BSDF with prefix= (CLI: --target)' if len(found) > 1 else ''}")
        out[name] = found[0]
    return out


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

    def __call__(self, S):
        """Differentiable loss of luminance Stokes images ``S`` (list of 4 tensors)."""
        import drjit as dr

        loss = dr.mean(self.mask * dr.square(S[0] - self.ref[0]), axis=None) / self.norm0
        if self.components == "stokes":
            pol = sum(dr.square(S[c] - self.ref[c]) for c in (1, 2, 3))
            loss = loss + dr.mean(self.mask * pol, axis=None) / self.normp
        return loss

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
        if progress and (it % 10 == 0 or it == iterations - 1):
            _log(f"it {it:4d}/{iterations}  loss {row['loss']:.3e}  " +
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
    with path.open("w", newline="") as fh:
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
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


# ---------------------------------------------------------------------------
# command line

def _parse_values(text, what):
    out = {}
    for item in filter(None, (s.strip() for s in text.split(","))):
        if "=" not in item:
            raise ValueError(f"{what}: expected name=value pairs like rms_slope=0.3,eta=1.5,k=3; got {item!r}")
        name, value = (s.strip() for s in item.split("=", 1))
        if name not in PARAMETERS:
            raise ValueError(f"{what}: unknown parameter {name!r}; use {', '.join(PARAMETERS)}")
        try:
            v = float(value)
        except ValueError:
            raise ValueError(f"{what}: {name}={value!r} is not a number") from None
        lo, hi = RANGES[name]
        if not (math.isfinite(v) and lo <= v <= hi):
            raise ValueError(f"{what}: {name}={v:g} is outside the accepted range [{lo:g}, {hi:g}]")
        out[name] = v
    return out


def build_parser():
    ap = argparse.ArgumentParser(
        prog="hyde-bsdf invert",
        description="Recover the hyde BSDF's rms_slope, eta, k (Mitsuba n + ik; the paper's eta = n - jk, "
                    "same numbers) from a Stokes image by differentiable rendering (llvm_ad_spectral_polarized).")
    ap.add_argument("--scene", default=None, help="Mitsuba XML scene with one hyde BSDF (default: the "
                    "built-in sphere scene, = scenes/inverse.xml)")
    ap.add_argument("--target", default=None, help="key prefix of the BSDF to recover when the scene has "
                    "several, e.g. sphere.bsdf (mi.traverse names)")
    ap.add_argument("--reference", default=None, help="reference Stokes EXR (hyde-bsdf render output) of "
                    "the same scene, resolution and camera; default: render one at --truth")
    ap.add_argument("--truth", default="rms_slope=0.3,eta=1.5,k=3",
                    help="parameters of the reference rendering (and errors are reported against them)")
    ap.add_argument("--start", default="rms_slope=0.6,eta=3,k=6", help="start values (name=value,...)")
    ap.add_argument("--fit", default="rms_slope,eta,k", help="parameters to optimize")
    ap.add_argument("--loss", default="stokes", choices=("stokes", "s0"),
                    help="stokes: all four Stokes components; s0: intensity only")
    ap.add_argument("--iterations", type=int, default=200)
    ap.add_argument("--spp", type=int, default=16)
    ap.add_argument("--spp-ref", type=int, default=512)
    ap.add_argument("--res", type=int, default=64, help="image size of the built-in scene")
    ap.add_argument("--lr", type=float, default=0.05, help="Adam learning rate (on log parameters)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("-o", "--output", default="out/invert", help="output folder")
    return ap


def cli_main(argv=None) -> int:
    """``hyde-bsdf invert``: reference, optimization, CSV + PNG of the trajectories."""
    args = build_parser().parse_args(argv)
    try:
        truth = {**TRUTH, **_parse_values(args.truth, "--truth")}
        start = {**START, **_parse_values(args.start, "--start")}
        fit = tuple(s.strip() for s in args.fit.split(",") if s.strip())
        bad = [p for p in fit if p not in PARAMETERS]
        if bad or not fit:
            raise ValueError(f"--fit must list parameters from {', '.join(PARAMETERS)}, got {args.fit!r}")
        for name, v in (("--iterations", args.iterations), ("--spp", args.spp),
                        ("--spp-ref", args.spp_ref), ("--res", args.res)):
            if v < 1:
                raise ValueError(f"{name} must be >= 1, got {v}")
        if not (args.lr > 0):
            raise ValueError(f"--lr must be > 0, got {args.lr}")
        prepare()
        kw = {"res": args.res, "spp": args.spp} if args.scene is None else {}
        scene = load_scene(args.scene, **kw)
        import mitsuba as mi

        parameter_keys(mi.traverse(scene), PARAMETERS, args.target)   # exactly one hyde BSDF, or a clear error
        if args.reference:
            from hyde_bsdf.render.stokes_io import read_stokes_exr

            st = read_stokes_exr(args.reference)
            ref = np.array([np.asarray(st[s], float) @ np.array(Y_WEIGHTS) for s in ("S0", "S1", "S2", "S3")])
            truth_known = args.truth != build_parser().get_default("truth")
        else:
            _log(f"rendering the reference at {truth} ({args.spp_ref} spp)")
            ref = render_reference(scene, truth, args.spp_ref, seed=args.seed, prefix=args.target)
            truth_known = True
        loss_fn = StokesLoss(ref, components=args.loss)
    except (ValueError, RuntimeError, OSError) as exc:
        print(f"hyde-bsdf invert: error: {exc}", file=sys.stderr)
        return 2
    res = invert(scene, loss_fn, start, fit=fit, iterations=args.iterations, lr=args.lr, spp=args.spp,
                 seed=args.seed, truth=truth if truth_known else None, prefix=args.target)
    out = Path(args.output)
    write_history(res, out / "invert_history.csv")
    plot_history({args.loss: res}, out / "invert.png",
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
    print(f"wrote {out / 'invert_history.csv'} and {out / 'invert.png'}")
    return 0

