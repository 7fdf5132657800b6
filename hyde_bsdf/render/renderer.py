"""Render a Mitsuba scene to a Stokes image: Python API and ``hyde-bsdf render``.

``render_stokes(scene_or_path, variant=..., spp=..., seed=...)`` renders with
Mitsuba's ``stokes`` integrator (the scene's own integrator is wrapped in one if
it is not already) in ``spp`` chunks, reporting each through a progress callback, and
returns the mean image and, from the spread between chunks, its Monte-Carlo
standard error.  In an *unpolarized* variant (``llvm_ad_rgb``, ``scalar_rgb``, ...) it
renders the ordinary colour image instead (a ``stokes`` wrapper in the scene is dropped).

Stokes basis of the result: Mitsuba's sensor basis (see :mod:`hyde_bsdf.io.stokes_exr`):
for light travelling towards the camera, S1 > 0 is polarization along the image
rows, S2 > 0 is at +45 deg counter-clockwise from image-right as seen by the
viewer.  :func:`hyde_bsdf.render.sensor_to_paper_rotation` re-expresses it in
the paper's (s, p, k) basis of a surface.

Checked before rendering (a :class:`~hyde_bsdf.errors.UsageError`, exit 2 on the command line):
the scene has a sensor and a *sampling* integrator (not ``ptracer``), the sampler's
``sample_count`` and ``spp`` are >= 1, the film is at least 1 x 1 and holds fewer than 2^32
values (Dr.Jit's array limit), and the estimated memory (:func:`~hyde_bsdf.resources.render_bytes`)
fits in ``MemAvailable``.  A render of more than :data:`MAX_SAMPLES_PER_PASS` samples is split into
passes (Mitsuba's own limit is 2^32 samples per pass, src/render/integrator.cpp, and a pass of
that size does not fit in memory).

The command line (``hyde-bsdf render SCENE.xml -o OUT.exr``: the EXR and its PNG charts) is :mod:`hyde_bsdf.app.render`.
"""
from __future__ import annotations

import contextlib
import math
import re
import signal
import threading
import time
import warnings
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np

from hyde_bsdf.errors import UsageError, one_line
from hyde_bsdf.io.input_gate import check_input
from hyde_bsdf.io.scene_files import scene_files
from hyde_bsdf.io.stokes_exr import STOKES_NAMES
from hyde_bsdf.progress import as_callback
from hyde_bsdf.resources import COSTS, check_memory, render_bytes

__all__ = ["DEFAULT_VARIANT", "prepare_variant", "load_scene", "load_scene_nearest", "render_stokes",
           "plan_passes", "sensor_to_paper_rotation", "rotate_stokes"]

DEFAULT_VARIANT = "llvm_ad_spectral_polarized"

#: Samples (pixels x spp) per ``mi.render`` call; more spp are split into passes.  Mitsuba's own
#: limit is 2^32 per pass (it then splits by itself, dropping samples when spp does not divide,
#: and divides by zero for films of >= 2^32 pixels); 2^26 keeps a pass to seconds.
MAX_SAMPLES_PER_PASS = 2**26
#: Chunk c of a render uses the Mitsuba seed ``seed * 2**16 + c``, so at most 2^16 passes.
MAX_PASSES = 2**16
#: Largest seed: ``seed * 2**16 + c`` must fit Mitsuba's 32-bit seed.
MAX_SEED = 2**15 - 1
#: Dr.Jit arrays hold fewer than 2^32 entries; the film holds pixels x channels floats.
MAX_FILM_VALUES = 2**32 - 1


def prepare_variant(variant: str = DEFAULT_VARIANT, fallback: bool = True) -> str:
    """Select a Mitsuba variant (LLVM checked, scalar fallback) and register ``hyde`` for it.

    Polarized variants (``*_polarized``) render Stokes images; the others render the colour
    image only.  Returns the variant actually set.  :class:`~hyde_bsdf.errors.UsageError`
    (a ValueError) for an unknown variant or one this machine cannot run (``cuda_*`` without a
    CUDA GPU -- never moved to the CPU silently --, ``llvm_*`` without a usable libLLVM and
    ``fallback=False``).
    """
    import mitsuba as mi

    from hyde_bsdf.mitsuba.variants import VariantUnavailable, set_variant

    if not isinstance(variant, str) or variant not in mi.variants():
        raise UsageError(f"variant must be one of this Mitsuba's variants ({', '.join(mi.variants())}), "
                         f"got {variant!r}")
    try:
        with warnings.catch_warnings():       # the fallback is reported below, in one line
            warnings.simplefilter("ignore", RuntimeWarning)
            # An explicit cuda_* request is not silently moved to the CPU: without a GPU it is
            # refused, naming the llvm_* twin; only llvm_* falls back (to scalar_*).
            chosen = set_variant(variant, fallback=fallback and not variant.startswith("cuda_"))
    except VariantUnavailable as exc:
        raise UsageError(one_line(exc)) from None
    except (ImportError, RuntimeError) as exc:  # cuda_* without a GPU: "CUDA backend hasn't been initialized"
        usable = [v for v in mi.variants() if not v.startswith("cuda_")]
        raise UsageError(f"variant {variant!r} cannot be used on this machine ({one_line(exc)[:160]}); "
                         f"use one of {', '.join(usable)}") from None
    if chosen != variant:
        warnings.warn(f"no usable LLVM back end: falling back to the {chosen!r} variant (slower)",
                      RuntimeWarning, stacklevel=2)
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


_PARAM = re.compile(r"\$([A-Za-z_][A-Za-z0-9_]*)")
#: Mitsuba integrators that are not sampling integrators (the stokes integrator and
#: ``mi.render``'s sampling path need one).
_NON_SAMPLING_INTEGRATORS = {"ptracer"}


class _SceneXML:
    """What :func:`load_scene` checks in the XML before Mitsuba sees it (``$name`` resolved)."""

    def __init__(self, path: Path, params: dict):
        self.path = path
        self.raw = {}   # "sample_count"/"width"/"height" -> raw attribute text of the first sensor
        self.values, self.params = dict(params), dict(params)
        try:
            text = path.read_text(encoding="utf-8", errors="replace")
        except OSError as exc:
            raise UsageError(f"scene {str(path)!r} cannot be read ({exc.strerror or exc})") from None
        # Mitsuba's parser (pugixml) accepts "--" inside comments, ElementTree does not.
        try:
            root = ET.fromstring(re.sub(r"<!--.*?-->", "", text, flags=re.S))
        except ET.ParseError:
            self.tree = None     # leave the diagnosis to Mitsuba's parser
            return
        self.tree = ET.ElementTree(root)
        if root.tag != "scene":
            raise UsageError(f"scene {str(path)!r}: the root element is <{root.tag}>, expected <scene>")
        self.values = {d.get("name"): d.get("value") for d in root.findall("default")}
        self.values.update(params)
        self.has_include = root.find(".//include") is not None
        self.sensors = root.findall(".//sensor")
        self.integrators = [e.get("type") for e in root.iter("integrator")]

    def resolve(self, text: str) -> str:
        return _PARAM.sub(lambda m: str(self.values.get(m.group(1), m.group(0))), text)

    def hint(self, key: str) -> str:
        """' (the scene's $NAME; set it with `params` NAME=N)' when the first sensor's ``key`` is a plain ``$NAME``."""
        m = _PARAM.fullmatch(self.raw.get(key, "") or "")
        return f" (the scene's ${m.group(1)}; set it with `params` {m.group(1)}=N)" if m else ""

    def check(self) -> None:
        scene_files(self.path, self.params)        # the input gate on every file of the graph
        if self.tree is None:
            return
        where = f"scene {str(self.path)!r}"
        if not self.sensors and not self.has_include:
            raise UsageError(f"{where} has no <sensor>: add a camera, e.g. <sensor type=\"perspective\"> "
                             "with a <film> and a <sampler>")
        bad = sorted({t for t in self.integrators if t in _NON_SAMPLING_INTEGRATORS})
        if bad:
            raise UsageError(f"{where}: integrator {bad[0]!r} is not supported by render -- it needs a "
                             "sampling integrator (path, direct, volpath, ...), which Mitsuba's stokes "
                             "integrator can wrap")
        if not self.sensors:
            return
        sensor = self.sensors[0]
        for tag, key, what in (("sampler", "sample_count", "the sampler's sample_count"),
                               ("film", "width", "the film width"), ("film", "height", "the film height")):
            el = sensor.find(f"{tag}/integer[@name='{key}']")
            if el is None or el.get("value") is None:
                continue
            self.raw[key] = el.get("value")
            try:
                value = int(self.resolve(el.get("value")))
            except ValueError:
                continue                         # not a plain integer: Mitsuba's parser reports it
            if value < 1:
                raise UsageError(f"{where}: {what} is {value}; it must be an integer >= 1{self.hint(key)}")

    def to_nearest(self, names) -> list:
        """Set ``filter_type`` ``nearest`` on every ``bitmap`` texture named in ``names`` (``alpha``,
        ``eta``, ...) that filters otherwise (Mitsuba's default is bilinear), in the parsed tree;
        returns the texture names changed (each once)."""
        changed = []
        if self.tree is None:
            return changed
        for tex in self.tree.getroot().iter("texture"):
            if tex.get("type") != "bitmap" or tex.get("name") not in names:
                continue
            ft = next((e for e in tex if e.tag == "string" and e.get("name") == "filter_type"), None)
            if ft is not None and ft.get("value") == "nearest":
                continue
            if ft is None:
                ft = ET.SubElement(tex, "string", name="filter_type")
            ft.set("value", "nearest")
            if tex.get("name") not in changed:
                changed.append(tex.get("name"))
        return changed

    def without_stokes(self) -> str | None:
        """The scene's XML with a top-level ``stokes`` integrator replaced by the integrator it
        wraps (``path`` if none): unpolarized variants refuse ``stokes``.  None if no change."""
        if self.tree is None:
            return None
        root = self.tree.getroot()
        for i, el in enumerate(list(root)):
            if el.tag == "integrator" and el.get("type") == "stokes":
                inner = el.find("integrator")
                root.remove(el)
                root.insert(i, inner if inner is not None else ET.Element("integrator", type="path"))
                return ET.tostring(root, encoding="unicode")
        return None


def load_scene(path, params: dict | None = None, polarized: bool | None = None):
    """``mi.load_file`` with the checks above and one-line errors; ``params`` fill the XML's
    ``$name`` defaults.  ``polarized`` (default: the current variant's) False drops a
    ``stokes`` integrator so that the scene loads in an unpolarized variant."""
    return _load_scene(path, params, polarized)[0]


def load_scene_nearest(path, names, params: dict | None = None, polarized: bool | None = None) -> tuple:
    """:func:`load_scene` with every ``bitmap`` texture named in ``names`` loaded with ``filter_type``
    ``nearest`` (what per-texel fitting assumes: a pixel inside a texel depends on that texel only);
    returns (scene, the texture names that filtered otherwise and were changed)."""
    scene, info = _load_scene(path, params, polarized, nearest=tuple(names))
    return scene, info.nearest_changed


def _load_scene(path, params=None, polarized=None, nearest=()):
    """:func:`load_scene`, also returning the checked XML (for the -D hints in messages)."""
    import mitsuba as mi

    path = Path(path)
    check_input(path, "scene file", stdin=False)   # the input gate: a regular file, size-limited
    if path.suffix.lower() != ".xml":
        raise UsageError(f"scene must be a Mitsuba .xml file, got {str(path)!r}")
    kwargs = {str(k): str(v) for k, v in (params or {}).items()}
    info = _SceneXML(path, kwargs)
    info.check()
    if polarized is None:
        polarized = (mi.variant() or "").endswith("_polarized")
    info.nearest_changed = info.to_nearest(nearest) if nearest else []
    text = None if polarized else info.without_stokes()
    if text is None and info.nearest_changed:
        text = ET.tostring(info.tree.getroot(), encoding="unicode")
    try:
        if text is None:
            scene = mi.load_file(str(path), **kwargs)
        else:
            resolver = mi.file_resolver()
            saved = [str(resolver[i]) for i in range(len(resolver))]
            resolver.prepend(str(path.resolve().parent))   # relative mesh/texture paths
            try:
                scene = mi.load_string(text, **kwargs)
            finally:
                resolver.clear()
                for folder in saved:
                    resolver.append(folder)
    except Exception as exc:  # Mitsuba raises RuntimeError/Exception with its parser's message
        raise UsageError(f"could not load scene {str(path)!r}: {one_line(exc)}") from None
    return scene, info


def _stokes_integrator(scene):
    """The scene's integrator if it is a ``stokes`` one, else a ``stokes`` wrapping it."""
    import mitsuba as mi

    integrator = scene.integrator()
    if "S0.R" in integrator.aov_names():
        return integrator
    return mi.load_dict({"type": "stokes", "integrator": integrator})


def plan_passes(width: int, height: int, spp: int, chunks: int | None = None) -> list[int]:
    """spp of each ``mi.render`` pass: ``chunks`` (default ``min(spp, 8)``) equal parts, or more
    so that a pass has at most :data:`MAX_SAMPLES_PER_PASS` samples.  UsageError beyond
    :data:`MAX_PASSES` passes."""
    pixels = int(width) * int(height)
    per_pass = max(1, MAX_SAMPLES_PER_PASS // max(pixels, 1))
    need = -(-spp // per_pass)
    n = max(min(spp, 8) if chunks is None else int(chunks), need)
    if n > MAX_PASSES:
        raise UsageError(f"spp={spp} on a {width}x{height} film needs {need} passes of at most {per_pass} "
                         f"spp (at most {MAX_SAMPLES_PER_PASS} samples each); at most {MAX_PASSES} passes "
                         f"are possible: lower `spp` to <= {MAX_PASSES * per_pass}")
    return [spp // n + (1 if c < spp % n else 0) for c in range(n)]


def _check_film(scene, polarized: bool, info=None) -> tuple[int, int]:
    """Film size >= 1 x 1, within Dr.Jit's array limit, and within the available memory."""
    sensor = scene.sensors()[0]
    film = sensor.film()
    width, height = (int(v) for v in film.crop_size())
    hint = (info.hint("width") or info.hint("height")) if info is not None else ""
    if width < 1 or height < 1:
        raise UsageError(f"the film is {width}x{height} pixels; width and height must be >= 1{hint}")
    channels = 20 if polarized else 5        # R, G, B, A, W (+ 12 Stokes) and a margin
    if width * height * channels > MAX_FILM_VALUES:
        raise UsageError(f"the {width}x{height} film is too large: {width * height * channels:.3g} values, "
                         f"Dr.Jit arrays hold at most 2^32 = {MAX_FILM_VALUES + 1:.3g}; at most "
                         f"{MAX_FILM_VALUES // channels:.3g} pixels{hint}")
    per_px = COSTS.render_stokes_bytes_per_pixel if polarized else COSTS.render_colour_bytes_per_pixel
    check_memory(render_bytes(width, height, polarized), f"rendering the {width}x{height} film (~{per_px} B/pixel)",
                 f"lower the film's width and height{hint or ' (its <film> width/height, or `params`)'}")
    return width, height


def _check_int(name, value, lo, hi=None):
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < lo or (
            hi is not None and value > hi):
        rng = f"an integer >= {lo}" if hi is None else f"an integer in [{lo}, {hi}]"
        raise UsageError(f"{name} must be {rng}, got {value!r}")
    return int(value)


@contextlib.contextmanager
def _ctrl_c_flag():
    """Record Ctrl-C during a render instead of raising at once: a KeyboardInterrupt raised in
    Python code that Mitsuba calls back (plugin constructors, BSDF tracing) can be lost inside
    Mitsuba/Dr.Jit, and Mitsuba's own handler cancels a pass and returns a partial image.  The
    caller checks the flag between steps.  Yields a function telling whether SIGINT arrived;
    main thread only."""
    flag = []
    if threading.current_thread() is not threading.main_thread():
        yield lambda: False
        return
    previous = signal.signal(signal.SIGINT, lambda signum, frame: flag.append(signum))
    try:
        yield lambda: bool(flag)
    finally:
        signal.signal(signal.SIGINT, previous)


def _render_pass(mi, scene, n, seed, integrator):
    try:
        return mi.render(scene, spp=n, seed=seed, integrator=integrator)
    except RuntimeError as exc:
        cause, msgs = exc, []
        while cause is not None:            # drjit.custom chains the real message as the cause
            if isinstance(cause, KeyboardInterrupt):
                raise cause from None       # Ctrl-C (or SIGTERM) inside mi.render's Python part
            msgs.append(one_line(cause))
            cause = cause.__cause__ or cause.__context__
        raise UsageError("Mitsuba could not render the scene: " + " <- ".join(msgs[::-1])[:600]) from exc


def render_stokes(scene_or_path, variant: str = DEFAULT_VARIANT, spp: int | None = None,
                  seed: int = 0, chunks: int | None = None, params: dict | None = None,
                  progress=True, fallback: bool = True, before_passes=None) -> dict:
    """Render a scene with the ``stokes`` integrator; return its Stokes image.

    Parameters
    ----------
    scene_or_path : path of a Mitsuba XML scene, or an already loaded ``mi.Scene``
        (then the current variant is used; ``variant`` is ignored).
    variant : Mitsuba variant for a path (default ``llvm_ad_spectral_polarized``; with
        ``fallback`` an unusable LLVM back end falls back to ``scalar_*`` with a message).
        An unpolarized variant (``llvm_ad_rgb``, ``scalar_rgb``, ...) renders the colour image
        only (a ``stokes`` integrator in the scene is replaced by the one it wraps).
    spp : samples per pixel (default: the scene sampler's ``sample_count``).
    seed : base seed in [0, 32767]; chunk ``c`` uses seed ``seed * 2**16 + c``.
    chunks : number of equal spp chunks (default ``min(spp, 8)``; more when a chunk would
        exceed :data:`MAX_SAMPLES_PER_PASS` samples); progress is reported after each, and the
        spread between chunks gives the Monte-Carlo error.
    params : ``$name`` values for the XML scene.
    progress : a callback ``progress(message)`` called after each chunk; True (the default) for
        ``[render] ...`` lines on stderr, False for none (:mod:`hyde_bsdf.progress`).
    before_passes : None, or ``before_passes(width, height, polarized)``, called once the scene is
        loaded and its film checked, before the first pass; what it raises ends the render there
        (the command line checks with it that the outputs' folder has room for that film).

    Returns
    -------
    dict with float32 arrays of shape (H, W, 3) (RGB per pixel, linear sRGB):
    ``"RGB"``, ``"S0".."S3"`` (the mean over all samples, Stokes components in the
    sensor's basis), ``"S0_sem".."S3_sem"`` (standard error of the mean from the
    chunk-to-chunk spread; zeros when ``chunks == 1``), and ``"meta"``: a dict
    (variant, polarized, spp, chunks, seed, seconds).  Unpolarized: ``"RGB"``, ``"RGB_sem"``
    and ``"meta"`` only.

    Raises :class:`~hyde_bsdf.errors.UsageError` (a ValueError) for the mistakes listed in the
    module docstring, before rendering.
    """
    with _ctrl_c_flag() as interrupted:
        return _render_stokes(scene_or_path, variant, spp, seed, chunks, params,
                              as_callback(progress, "[render]"), fallback,
                              interrupted, before_passes)


def _scene_of(mi, scene_or_path, variant, params, fallback, interrupted):
    """(scene, film info or None, variant) of a path (variant set, XML loaded) or a loaded scene."""
    def check_interrupt():
        if interrupted():
            raise KeyboardInterrupt

    if isinstance(scene_or_path, (str, Path)):
        variant = prepare_variant(variant, fallback=fallback)
        check_interrupt()
        scene, info = _load_scene(scene_or_path, params)
        check_interrupt()
        return scene, info, variant
    if not isinstance(scene_or_path, mi.Scene):
        raise UsageError(f"scene_or_path must be an XML path or a mi.Scene, got {type(scene_or_path).__name__}")
    return scene_or_path, None, mi.variant()


def _accumulate(mi, scene, integrator, sizes, seed, progress, interrupted):
    """Render the passes ``sizes`` (spp each); (sum of n * image, sum of n * image^2, channel
    names, seconds), float64 accumulators with one float32 temporary at a time."""
    sensor = scene.sensors()[0]
    spp = sum(sizes)
    t0 = time.perf_counter()
    names = acc = acc2 = None
    done = 0
    for c, n in enumerate(sizes):
        img = np.asarray(_render_pass(mi, scene, n, seed * 2**16 + c, integrator), dtype=np.float32)
        if interrupted() or integrator.should_stop():
            # Mitsuba's own SIGINT handler cancels the pass and returns a partial image:
            # never average that in; stop here.
            raise KeyboardInterrupt
        if names is None:
            names = [f.name for f in sensor.film().bitmap().struct_()]
            acc = np.zeros(img.shape, np.float64)
            acc2 = np.zeros(img.shape, np.float64)
        acc += n * img
        img *= img
        acc2 += n * img
        del img
        done += n
        if progress:
            el = time.perf_counter() - t0
            progress(f"{done:6d}/{spp} spp ({c + 1}/{len(sizes)} chunks)  {el:6.1f} s elapsed, "
                     f"~{el / done * (spp - done):5.1f} s left")
    return acc, acc2, names, time.perf_counter() - t0


def _mean_and_sem(acc, acc2, spp, chunks):
    """The mean image and its standard error from the chunk-to-chunk spread (in place)."""
    mean = acc
    mean /= spp
    if chunks == 1:
        return mean, np.zeros_like(mean)
    # Weighted spread of chunk means; a chunk of n samples has variance sigma^2 / n:
    # sem^2 = (E[x^2] - mean^2) / (chunks - 1), computed in place in acc2.
    sem = acc2
    sem /= spp
    sem -= mean * mean
    np.maximum(sem, 0.0, out=sem)
    sem /= chunks - 1
    np.sqrt(sem, out=sem)
    return mean, sem


def _split_channels(mean, sem, names, polarized) -> dict:
    """``RGB`` and ``S0..S3`` (with ``_sem``) arrays (H, W, 3) from the film's channels."""
    index = {name: i for i, name in enumerate(names)}
    out: dict = {}
    # Mono variants write one luminance channel "Y" instead of R, G, B.
    rgb_idx = [index[c] for c in ("R", "G", "B")] if "R" in index else [index["Y"]] * 3
    out["RGB"] = mean[..., rgb_idx].astype(np.float32)
    if not polarized:
        out["RGB_sem"] = sem[..., rgb_idx].astype(np.float32)
        return out
    for s in STOKES_NAMES:
        idx = [index[f"{s}.{c}"] for c in ("R", "G", "B")]
        out[s] = mean[..., idx].astype(np.float32)
        out[s + "_sem"] = sem[..., idx].astype(np.float32)
    return out


def _render_stokes(scene_or_path, variant, spp, seed, chunks, params, progress, fallback, interrupted,
                   before_passes=None):
    import mitsuba as mi

    scene, info, variant = _scene_of(mi, scene_or_path, variant, params, fallback, interrupted)
    polarized = variant.endswith("_polarized")
    if not scene.sensors():
        raise UsageError("the scene has no sensor: add a camera, e.g. <sensor type=\"perspective\">")
    if not isinstance(scene.integrator(), mi.SamplingIntegrator):
        raise UsageError(f"the scene's integrator ({type(scene.integrator()).__name__}) is not a sampling "
                         "integrator; render needs path, direct, volpath, ... (or stokes around one)")
    if spp is None:
        spp = int(scene.sensors()[0].sampler().sample_count())
    spp = _check_int("spp", spp, 1)
    if chunks is not None:
        chunks = _check_int("chunks", chunks, 1, spp)
    seed = _check_int("seed", seed, 0, MAX_SEED)
    width, height = _check_film(scene, polarized, info)
    sizes = plan_passes(width, height, spp, chunks)
    if before_passes is not None:
        before_passes(width, height, polarized)
    integrator = _stokes_integrator(scene) if polarized else scene.integrator()
    acc, acc2, names, seconds = _accumulate(mi, scene, integrator, sizes, seed, progress, interrupted)
    mean, sem = _mean_and_sem(acc, acc2, spp, len(sizes))
    if not np.all(np.isfinite(mean)):
        raise UsageError("the render produced non-finite pixel values (NaN/Inf) -- "
                         "a BSDF or emitter in the scene returned invalid values")
    out = _split_channels(mean, sem, names, polarized)
    out["meta"] = {"variant": variant, "polarized": polarized, "spp": spp, "chunks": len(sizes),
                   "seed": int(seed), "seconds": round(seconds, 3)}
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
        raise UsageError("up must not be parallel to ray_d (the sensor basis is undefined)")
    x_m /= np.linalg.norm(x_m)
    s_r = np.cross(k, z)
    if np.linalg.norm(s_r) < 1e-7:
        # Normal viewing: the paper takes the limit at fixed azimuth phi_r, where
        # k x z -> (sin phi_r, -cos phi_r, 0) for z = (0, 0, 1).
        if phi_r is None:
            raise UsageError("phi_r is needed when the view direction is along the normal")
        if not np.allclose(z, (0.0, 0.0, 1.0)):
            raise UsageError("phi_r is only supported for normal = (0, 0, 1)")
        s_r = np.array([math.sin(phi_r), -math.cos(phi_r), 0.0])
    s_r = s_r / np.linalg.norm(s_r)
    # Signed angle from x_m to s_r about k (both are perpendicular to k).
    return math.atan2(float(np.dot(k, np.cross(x_m, s_r))), float(np.dot(x_m, s_r)))


