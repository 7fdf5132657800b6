"""Render a Mitsuba scene to a Stokes image: Python API and ``hyde-bsdf render``.

``render_stokes(scene_or_path, variant=..., spp=..., seed=...)`` renders with
Mitsuba's ``stokes`` integrator (the scene's own integrator is wrapped in one if
it is not already) in ``spp`` chunks, showing a progress line on stderr, and
returns the mean image and, from the spread between chunks, its Monte-Carlo
standard error.

Stokes basis of the result: Mitsuba's sensor basis (see :mod:`hyde_bsdf.render.stokes_io`):
for light travelling towards the camera, S1 > 0 is polarization along the image
rows, S2 > 0 is at +45 deg counter-clockwise from image-right as seen by the
viewer.  :func:`hyde_bsdf.render.sensor_to_paper_rotation` re-expresses it in
the paper's (s, p, k) basis of a surface.

Command line::

    hyde-bsdf render SCENE.xml -o OUT.exr [--variant V] [--spp N] [--seed S]
                     [--chunks C] [-D name=value ...] [--no-png]

writes ``OUT.exr`` (channels R, G, B, S0.R ... S3.B, float32) and
``OUT_intensity.png``, ``OUT_dolp.png``, ``OUT_aolp.png``, ``OUT_docp.png``,
``OUT_rgb.png``.
"""
from __future__ import annotations

import argparse
import math
import sys
import time
from pathlib import Path

import numpy as np

from hyde_bsdf.render.stokes_io import STOKES_NAMES, save_polarization_pngs, write_stokes_exr

__all__ = ["DEFAULT_VARIANT", "prepare_variant", "load_scene", "render_stokes",
           "sensor_to_paper_rotation", "rotate_stokes", "cli_main"]

DEFAULT_VARIANT = "llvm_ad_spectral_polarized"


def _log(msg: str) -> None:
    print(f"[render] {msg}", file=sys.stderr, flush=True)


def prepare_variant(variant: str = DEFAULT_VARIANT, fallback: bool = True) -> str:
    """Select a *polarized* Mitsuba variant (LLVM checked, scalar fallback) and register ``hyde``.

    Returns the variant actually set.  ValueError for an unknown or unpolarized variant.
    """
    import mitsuba as mi

    from hyde_bsdf.mitsuba.variants import VariantUnavailable, set_variant

    if not isinstance(variant, str) or not variant.endswith("_polarized"):
        pol = [v for v in mi.variants() if v.endswith("_polarized")]
        raise ValueError(f"variant must be a polarized Mitsuba variant (one of {', '.join(pol)}), "
                         f"got {variant!r}")
    try:
        chosen = set_variant(variant, fallback=fallback)
    except VariantUnavailable as exc:
        raise ValueError(str(exc)) from None
    if chosen != variant:
        _log(f"no usable LLVM back end: falling back to the {chosen!r} variant (slower)")
    _register_hyde()
    return chosen


def _register_hyde() -> bool:
    """Register the ``hyde`` BSDF for the current variant; False if the plugin is not installed."""
    try:
        from hyde_bsdf.mitsuba.plugin import register
    except ModuleNotFoundError as exc:
        if exc.name and exc.name.endswith("plugin"):
            return False
        raise
    register()
    return True


def load_scene(path, params: dict | None = None):
    """``mi.load_file`` with clear errors; ``params`` fill the XML's ``$name`` defaults."""
    import mitsuba as mi

    path = Path(path)
    if not path.is_file():
        raise ValueError(f"scene file {str(path)!r} does not exist")
    if path.suffix.lower() != ".xml":
        raise ValueError(f"scene must be a Mitsuba .xml file, got {str(path)!r}")
    kwargs = {str(k): str(v) for k, v in (params or {}).items()}
    try:
        return mi.load_file(str(path), **kwargs)
    except Exception as exc:  # Mitsuba raises RuntimeError/Exception with its parser's message
        raise ValueError(f"could not load scene {str(path)!r}: {exc}") from None


def _stokes_integrator(scene):
    """The scene's integrator if it is a ``stokes`` one, else a ``stokes`` wrapping it."""
    import mitsuba as mi

    integrator = scene.integrator()
    if "S0.R" in integrator.aov_names():
        return integrator
    return mi.load_dict({"type": "stokes", "integrator": integrator})


def render_stokes(scene_or_path, variant: str = DEFAULT_VARIANT, spp: int | None = None,
                  seed: int = 0, chunks: int | None = None, params: dict | None = None,
                  progress: bool = True, fallback: bool = True) -> dict:
    """Render a scene with the ``stokes`` integrator; return its Stokes image.

    Parameters
    ----------
    scene_or_path : path of a Mitsuba XML scene, or an already loaded ``mi.Scene``
        (then the current variant is used and must be polarized; ``variant`` is ignored).
    variant : polarized Mitsuba variant for a path (default ``llvm_ad_spectral_polarized``;
        with ``fallback`` an unusable LLVM back end falls back to ``scalar_*`` with a message).
    spp : samples per pixel (default: the scene sampler's ``sample_count``).
    seed : base seed; chunk ``c`` uses seed ``seed * 2**16 + c``.
    chunks : number of equal spp chunks (default ``min(spp, 8)``); progress is reported
        after each, and the spread between chunks gives the Monte-Carlo error.
    params : ``$name`` values for the XML scene.

    Returns
    -------
    dict with float32 arrays of shape (H, W, 3) (RGB per pixel, linear sRGB):
    ``"RGB"``, ``"S0".."S3"`` (the mean over all samples, Stokes components in the
    sensor's basis), ``"S0_sem".."S3_sem"`` (standard error of the mean from the
    chunk-to-chunk spread; zeros when ``chunks == 1``), and ``"meta"``: a dict
    (variant, spp, chunks, seed, seconds).
    """
    import mitsuba as mi

    if isinstance(scene_or_path, (str, Path)):
        variant = prepare_variant(variant, fallback=fallback)
        scene = load_scene(scene_or_path, params)
    else:
        if not isinstance(scene_or_path, mi.Scene):
            raise ValueError(f"scene_or_path must be an XML path or a mi.Scene, "
                             f"got {type(scene_or_path).__name__}")
        variant = mi.variant()
        if not variant.endswith("_polarized"):
            raise ValueError(f"rendering Stokes images needs a polarized variant; "
                             f"the current one is {variant!r}")
        scene = scene_or_path
    sensor = scene.sensors()[0]
    if spp is None:
        spp = int(sensor.sampler().sample_count())
    if isinstance(spp, bool) or not isinstance(spp, (int, np.integer)) or spp < 1:
        raise ValueError(f"spp must be an integer >= 1, got {spp!r}")
    spp = int(spp)
    if chunks is None:
        chunks = min(spp, 8)
    if isinstance(chunks, bool) or not isinstance(chunks, (int, np.integer)) or not 1 <= chunks <= spp:
        raise ValueError(f"chunks must be an integer in [1, spp={spp}], got {chunks!r}")
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or not 0 <= seed < 2**15:
        raise ValueError(f"seed must be an integer in [0, 32767], got {seed!r}")
    chunks = int(chunks)
    integrator = _stokes_integrator(scene)
    # Split spp as evenly as possible; chunk means are weighted by their spp.
    sizes = [spp // chunks + (1 if c < spp % chunks else 0) for c in range(chunks)]

    t0 = time.perf_counter()
    names = None
    acc = acc2 = None
    done = 0
    for c, n in enumerate(sizes):
        img = np.array(mi.render(scene, spp=n, seed=int(seed) * 2**16 + c, integrator=integrator),
                       dtype=np.float64)
        if names is None:
            names = [f.name for f in sensor.film().bitmap().struct_()]
            acc = np.zeros_like(img)
            acc2 = np.zeros_like(img)
        acc += n * img
        acc2 += n * img * img
        done += n
        if progress:
            el = time.perf_counter() - t0
            left = el / done * (spp - done)
            end = "\n" if c == chunks - 1 else "\r"
            print(f"[render] {done:6d}/{spp} spp ({c + 1}/{chunks} chunks)  {el:6.1f} s elapsed, "
                  f"~{left:5.1f} s left", file=sys.stderr, end=end, flush=True)
    seconds = time.perf_counter() - t0
    mean = acc / spp
    if chunks > 1:
        # Weighted spread of chunk means; a chunk of n samples has variance sigma^2 / n.
        var_sample = np.maximum(acc2 / spp - mean**2, 0.0) * spp / (chunks - 1)
        sem = np.sqrt(var_sample / spp)
    else:
        sem = np.zeros_like(mean)
    if not np.all(np.isfinite(mean)):
        raise ValueError("the render produced non-finite pixel values (NaN/Inf) -- "
                         "a BSDF or emitter in the scene returned invalid values")

    index = {name: i for i, name in enumerate(names)}
    out: dict = {}
    # Mono variants write one luminance channel "Y" instead of R, G, B.
    rgb_idx = [index[c] for c in ("R", "G", "B")] if "R" in index else [index["Y"]] * 3
    out["RGB"] = mean[..., rgb_idx].astype(np.float32)
    for s in STOKES_NAMES:
        idx = [index[f"{s}.{c}"] for c in ("R", "G", "B")]
        out[s] = mean[..., idx].astype(np.float32)
        out[s + "_sem"] = sem[..., idx].astype(np.float32)
    out["meta"] = {"variant": variant, "spp": spp, "chunks": chunks, "seed": int(seed),
                   "seconds": round(seconds, 3)}
    return out


def rotate_stokes(s1, s2, angle):
    """Re-express (S1, S2) in a basis rotated by ``angle`` (radians) about the propagation axis.

    ``angle`` is the counter-clockwise angle, seen by the viewer (right-handed about the
    propagation direction k), from the current first basis vector to the new one.
    Same convention as Mitsuba's ``mueller.rotator(angle)``:
    S1' = cos(2a) S1 + sin(2a) S2,  S2' = -sin(2a) S1 + cos(2a) S2;  S0 and S3 unchanged.
    """
    c, s = np.cos(2 * np.asarray(angle)), np.sin(2 * np.asarray(angle))
    return c * s1 + s * s2, -s * s1 + c * s2


def sensor_to_paper_rotation(ray_d, up, normal=(0.0, 0.0, 1.0), phi_r=None):
    """Angle from Mitsuba's sensor Stokes basis to the paper's (s_r, p_r) basis.

    Mitsuba's ``stokes`` integrator reports the Stokes vector of light travelling along
    ``k = -ray_d`` (towards the camera) in the basis with first vector
    ``x_m = normalize(ray_d x up)`` (``up``: the sensor's up axis in world space;
    src/integrators/stokes.cpp) and second ``k x x_m``.  The paper's basis for the
    reflected wave is ``s_r = normalize(k_r x z)``, ``p_r = k_r x s_r`` with ``k_r = -ray_d``
    and ``z`` the mean surface normal; both bases are right-handed about ``k``
    (first x second = k), so they differ by one rotation about ``k``.

    Returns the angle a (radians) with S_paper = rotator(a) S_sensor (see
    :func:`rotate_stokes`).  When ``k`` is parallel to ``normal`` the paper's basis is the
    limit at fixed azimuth; pass ``phi_r`` (the observer's azimuth about ``normal``,
    measured from the world x axis in the plane z=normal) to select it.
    """
    ray_d = np.asarray(ray_d, dtype=float)
    up = np.asarray(up, dtype=float)
    z = np.asarray(normal, dtype=float)
    z = z / np.linalg.norm(z)
    k = -ray_d / np.linalg.norm(ray_d)
    x_m = np.cross(ray_d, up)
    if np.linalg.norm(x_m) < 1e-9:
        raise ValueError("up must not be parallel to ray_d (the sensor basis is undefined)")
    x_m /= np.linalg.norm(x_m)
    s_r = np.cross(k, z)
    if np.linalg.norm(s_r) < 1e-7:
        # Normal viewing: the paper takes the limit at fixed azimuth phi_r, where
        # k x z -> (sin phi_r, -cos phi_r, 0) for z = (0, 0, 1).
        if phi_r is None:
            raise ValueError("phi_r is needed when the view direction is along the normal")
        if not np.allclose(z, (0.0, 0.0, 1.0)):
            raise ValueError("phi_r is only supported for normal = (0, 0, 1)")
        s_r = np.array([math.sin(phi_r), -math.cos(phi_r), 0.0])
    s_r = s_r / np.linalg.norm(s_r)
    # Signed angle from x_m to s_r about k (both are perpendicular to k).
    return math.atan2(float(np.dot(k, np.cross(x_m, s_r))), float(np.dot(x_m, s_r)))


def _parse_define(text: str) -> tuple[str, str]:
    if "=" not in text or not text.split("=", 1)[0].strip():
        raise argparse.ArgumentTypeError(f"-D expects name=value, got {text!r}")
    name, value = text.split("=", 1)
    return name.strip(), value.strip()


def _positive_int(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected an integer >= 1, got {text!r}") from None
    if value < 1:
        raise argparse.ArgumentTypeError(f"expected an integer >= 1, got {value}")
    return value


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="hyde-bsdf render",
        description="Render a Mitsuba scene to a Stokes EXR (R,G,B,S0.R..S3.B, float32) and PNG "
                    "charts of intensity, DoLP, AoLP and DoCP.  The scene may use the 'hyde' BSDF.")
    p.add_argument("scene", help="Mitsuba 3 scene (.xml)")
    p.add_argument("-o", "--output", required=True, help="output EXR path (must end in .exr)")
    p.add_argument("--variant", default=DEFAULT_VARIANT,
                   help=f"polarized Mitsuba variant (default {DEFAULT_VARIANT}; falls back to "
                        "scalar_spectral_polarized without a usable libLLVM)")
    p.add_argument("--spp", type=_positive_int, default=None,
                   help="samples per pixel (default: the scene's sampler)")
    p.add_argument("--seed", type=int, default=0, help="random seed, 0..32767 (default 0)")
    p.add_argument("--chunks", type=_positive_int, default=None,
                   help="render in this many spp chunks (progress + error estimate; default min(spp, 8))")
    p.add_argument("-D", dest="define", action="append", type=_parse_define, default=[],
                   metavar="NAME=VALUE", help="set a $NAME default of the scene (repeatable)")
    p.add_argument("--no-png", action="store_true", help="write only the EXR")
    return p


def cli_main(argv=None) -> int:
    """``hyde-bsdf render``: returns 0 on success, 2 on bad arguments or a failed render."""
    parser = build_parser()
    try:
        args = parser.parse_args(argv)
    except SystemExit as exc:  # argparse prints its message; hand back its code
        return int(exc.code or 0)
    out = Path(args.output)
    if out.suffix.lower() != ".exr":
        print(f"hyde-bsdf render: error: --output must end in .exr, got {args.output!r}", file=sys.stderr)
        return 2
    if not Path(args.scene).is_file():
        print(f"hyde-bsdf render: error: scene file {args.scene!r} does not exist", file=sys.stderr)
        return 2
    try:
        result = render_stokes(args.scene, variant=args.variant, spp=args.spp, seed=args.seed,
                               chunks=args.chunks, params=dict(args.define))
    except ValueError as exc:
        print(f"hyde-bsdf render: error: {exc}", file=sys.stderr)
        return 2
    meta = result["meta"]
    write_stokes_exr(out, result, metadata=meta)
    written = [out]
    if not args.no_png:
        stem = out.with_suffix("")
        written += list(save_polarization_pngs(result, stem, title=Path(args.scene).stem).values())
    _log(f"{meta['spp']} spp in {meta['seconds']:.1f} s ({meta['variant']}); wrote "
         + ", ".join(str(p) for p in written))
    return 0
