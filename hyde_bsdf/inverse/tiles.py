"""Texture-valued inversion in tiles of texels, each an independent task on an executor.

With nearest-neighbour texels a pixel that lies wholly inside the texels of one tile depends on
those texels only, so the per-texel problem separates: a tile of texels is fitted from the pixels
that lie wholly inside it, and from nothing else.  :func:`invert_maps_tiled` splits the map into
``tiles`` = (rows, columns) rectangles of texels, finds for every picture the pixels wholly inside
each tile (one ray per pixel corner: a pixel whose four corners land in the tile's texels lies in
it, the tile being convex in UV and the plane's projection straight-line preserving), and gives
each tile one task: render only the film crop (Mitsuba's ``crop_offset_x/y``, ``crop_width/height``)
that holds its pixels, fit only its texels (:func:`~hyde_bsdf.inverse.maps.invert_maps` on the
cropped observations, the other pixels of the crop out of the loss), with the standard errors.  The
results -- maps, standard errors, converged flags, the seen mask -- are stitched, and the warnings
said once for the whole map.  The pixels that straddle two tiles are in no tile's loss (a line of
pixels along each tile boundary: for 4 x 4 tiles on a 1224 x 1024 picture ~7 000 of its 1.25 M pixels,
0.5 %; the texels along it keep their other pixels).

What a task receives is picklable, so the tasks run on any ``concurrent.futures`` executor through
the MoM's machinery (:func:`hyde_bsdf.mom.gather.gather`: liveness checks, a timeout, one-line
:class:`~hyde_bsdf.mom.gather.ExecutorError`): :class:`~hyde_bsdf.mom.solver.SerialExecutor` (the
default: in this process, one tile after the other), :func:`~hyde_bsdf.mom.solver.process_pool`, or a
dask cluster's ``client.get_executor()``.  The task rebuilds its scenes from the calibrated capture
(:class:`Capture`: the sample's XML path, the :class:`~hyde_bsdf.render.camera.Calibration` and
:class:`~hyde_bsdf.render.camera.Light` records, and the tile's crop of each reference, sigma and
mask), never from a live Mitsuba scene, which cannot be pickled.

Randomness: every task renders with the seeds :func:`invert_maps` derives from ``seed``; the result
of a tile does not depend on the executor that ran it (tests/test_inverse_tiles.py: serial and dask
agree to float noise).  Against the untiled run the sample pattern differs (a crop renders other
random numbers), so the tiled maps agree with it within the standard errors, not bit for bit.

Memory: each task holds one differentiable render of its crops; the largest tile's estimate
(:func:`~hyde_bsdf.resources.inversion_bytes`) times the workers that run at once is checked against
the available memory before any task starts.
"""
from __future__ import annotations

import dataclasses
import gc
import resource
import threading
import time
import warnings
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from hyde_bsdf.errors import UsageError, UsageTypeError
from hyde_bsdf.inverse.maps import MapInversionResult, invert_maps
from hyde_bsdf.inverse.observations import MAP_VARIANT, Observation, map_keys, pixel_texels
from hyde_bsdf.inverse.uncertainty import CONVERGENCE_THRESHOLD, STDERR_THRESHOLD, identification_warnings
from hyde_bsdf.progress import as_callback
from hyde_bsdf.resources import check_memory, inversion_bytes

__all__ = ["Capture", "Tile", "tile_bounds", "pixel_tiles", "plan_tiles", "run_tile", "invert_maps_tiled", "stitch_tiles"]

#: one tile at a time per process: Dr.Jit's AD graph and Mitsuba's variant are per process, and two
#: tasks rendering at once in threads of one process (a dask worker with several threads, or a thread
#: cluster) fail (measured: "operation on underlying array failed"); processes run in parallel
_ONE_AT_A_TIME = threading.Lock()
#: rows of pixels per batch of corner rays when the pixels are assigned to tiles (bounds the memory)
ROWS_PER_BATCH = 64


@dataclass(frozen=True)
class Capture:
    """A calibrated capture as a task can rebuild it: the sample's XML file (no sensor, no emitter:
    :func:`~hyde_bsdf.render.camera.calibrated_scene`), the cameras and the lights, and the references
    light-major (for each light, one per camera) as :func:`~hyde_bsdf.inverse.camera_data.camera_reference`
    returns them (``reference`` (4, H, W), ``measured``, ``sigma``, ``mask``).  ``spp``: the sensors'
    sample count; ``variant``: the Mitsuba variant the tasks select.  All picklable."""

    scene: str
    cameras: tuple
    lights: tuple
    references: tuple = ()
    spp: int = 4
    variant: str = MAP_VARIANT

    @classmethod
    def from_files(cls, scene, cameras, lights, references, *, masks=None, channel: str = "Y",
                   spp: int = 4) -> "Capture":
        """What ``invert --maps --scene --camera --light --reference ...`` reads, checked before any
        rendering (:func:`~hyde_bsdf.inverse.camera_data.camera_files`)."""
        from hyde_bsdf.inverse.camera_data import camera_files

        cams, lts, data = camera_files(cameras, lights, references, masks=masks, channel=channel)
        return cls(str(Path(scene).resolve()), tuple(cams), tuple(lts), tuple(tuple(row) for row in data), int(spp))

    def scene_of(self, light: int, camera: int, crop=None):
        """The Mitsuba scene of one light and one camera (sensor 0), its film cropped to ``crop`` =
        (x0, y0, width, height) when given."""
        from hyde_bsdf.render.camera import calibrated_scene

        film = None if crop is None else {"crop_offset_x": int(crop[0]), "crop_offset_y": int(crop[1]),
                                          "crop_width": int(crop[2]), "crop_height": int(crop[3])}
        return calibrated_scene(self.scene, [self.cameras[camera]], self.lights[light], spp=self.spp, film=film)

    def observations(self, first=None) -> list:
        """The whole pictures as observations, light-major, one scene each (sensor 0); the loss mask is
        :func:`~hyde_bsdf.inverse.camera_data.camera_observation`'s.  ``first``: the scene of light 0,
        camera 0 when already loaded."""
        from hyde_bsdf.inverse.camera_data import _stokes_dict, camera_observation

        return [camera_observation(first if first is not None and (j, i) == (0, 0) else self.scene_of(j, i),
                                   _stokes_dict(self.references[j][i]))
                for j in range(len(self.lights)) for i in range(len(self.cameras))]


@dataclass(frozen=True)
class Tile:
    """One task: texel rows r0:r1 and columns c0:c1 of the map, and per picture that sees them
    (light j, camera i) the crop (x0, y0, w, h) with the cropped reference, sigma and loss mask."""

    index: int
    bounds: tuple                # (r0, r1, c0, c1)
    capture: Capture             # without its references (each crop travels alone)
    crops: tuple                 # (j, i, (x0, y0, w, h), reference, measured, sigma, mask)
    start: dict
    fit: tuple
    prefix: str | None
    options: dict

    @property
    def pixels(self) -> int:
        return int(sum(c[2][2] * c[2][3] for c in self.crops))


def tile_bounds(shape, tiles) -> list:
    """[(r0, r1, c0, c1)] of ``tiles`` = (rows, columns) of tiles (or one number, n x n) over a map
    of ``shape`` (rows, columns), row-major, sizes differing by at most one texel."""
    if isinstance(tiles, (int, np.integer)) and not isinstance(tiles, bool):
        tiles = (int(tiles), int(tiles))
    if (not isinstance(tiles, tuple) or len(tiles) != 2
            or not all(isinstance(t, (int, np.integer)) and not isinstance(t, bool) for t in tiles)):
        raise UsageTypeError(f"tiles must be an integer or a pair of integers (rows, columns), got {tiles!r}")
    rows, cols = int(shape[0]), int(shape[1])
    ty, tx = int(tiles[0]), int(tiles[1])
    if not (1 <= ty <= rows and 1 <= tx <= cols):
        raise UsageError(f"tiles must be 1..{rows} x 1..{cols} for a {rows} x {cols}-texel map, got {ty} x {tx}")
    re = np.linspace(0, rows, ty + 1).round().astype(int)
    ce = np.linspace(0, cols, tx + 1).round().astype(int)
    return [(int(re[a]), int(re[a + 1]), int(ce[b]), int(ce[b + 1])) for a in range(ty) for b in range(tx)]


def pixel_tiles(obs: Observation, shape, bounds, prefix: str | None = None) -> np.ndarray:
    """(H, W) int: the index (into ``bounds``) of the tile that pixel lies wholly inside, -1 where it
    is outside the loss mask, straddles two tiles or is not wholly on the target shape.  One ray per
    pixel corner (inset 1e-3 px; :func:`~hyde_bsdf.inverse.observations.pixel_texels` with ``sub=2,
    edges=True``), ``ROWS_PER_BATCH`` pixel rows at a time."""
    rows, cols = int(shape[0]), int(shape[1])
    texel_tile = np.full(rows * cols, -1, np.int64)
    for t, (r0, r1, c0, c1) in enumerate(bounds):
        texel_tile.reshape(rows, cols)[r0:r1, c0:c1] = t
    mask = np.asarray(obs.mask, bool)
    H, W = mask.shape
    out = np.full(H * W, -1, np.int64)
    for y0 in range(0, H, ROWS_PER_BATCH):
        band = np.zeros_like(mask)
        band[y0:y0 + ROWS_PER_BATCH] = mask[y0:y0 + ROWS_PER_BATCH]
        if not band.any():
            continue
        pix, tex = pixel_texels(dataclasses.replace(obs, mask=band), shape, prefix, sub=2, edges=True)
        tile = texel_tile[tex]
        hits = np.bincount(pix, minlength=H * W)
        lo = np.full(H * W, np.iinfo(np.int64).max)
        hi = np.full(H * W, -1)
        np.minimum.at(lo, pix, tile)
        np.maximum.at(hi, pix, tile)
        whole = (hits == 4) & (lo == hi)
        out[whole] = hi[whole]
    return out.reshape(H, W)


def plan_tiles(capture: Capture, start: dict, *, fit=("alpha",), tiles=(2, 2), prefix: str | None = None,
               options: dict | None = None):
    """(tasks, map shape, observations' pixel counts): the :class:`Tile` tasks of a capture (tiles
    that no picture sees wholly get none), built in this process from the whole pictures."""
    import mitsuba as mi

    first = capture.scene_of(0, 0)             # the map's size and the tiles checked before the other scenes load
    params = mi.traverse(first)
    keys = map_keys(params, tuple(fit), prefix)
    shape = next((tuple(params[keys[n]].shape[:2]) for n in fit if isinstance(params[keys[n]], mi.TensorXf)), None)
    if shape is None:
        raise UsageError(f"tiles need a texture-valued fitted parameter; {', '.join(fit)} are constants in the scene")
    bounds = tile_bounds(shape, tiles)
    observations = capture.observations(first)
    light_cam = [(j, i) for j in range(len(capture.lights)) for i in range(len(capture.cameras))]
    owner = [pixel_tiles(o, shape, bounds, prefix) for o in observations]
    bare = dataclasses.replace(capture, references=())
    tasks = []
    for t, b in enumerate(bounds):
        crops = []
        for (j, i), o, own in zip(light_cam, observations, owner):
            ys, xs = np.nonzero(own == t)
            if ys.size == 0:
                continue
            y0, y1, x0, x1 = ys.min(), ys.max() + 1, xs.min(), xs.max() + 1
            cut = (slice(None), slice(y0, y1), slice(x0, x1))
            crops.append((j, i, (int(x0), int(y0), int(x1 - x0), int(y1 - y0)), np.array(o.reference[cut]),
                          tuple(o.measured), None if o.sigma is None else np.array(o.sigma[cut]),
                          np.array(own[y0:y1, x0:x1] == t)))
        if crops:
            tasks.append(Tile(t, b, bare, tuple(crops), dict(start), tuple(fit), prefix, dict(options or {})))
    return tasks, shape, [int(np.asarray(o.mask).sum()) for o in observations]


def run_tile(task: Tile) -> dict:
    """One tile's inversion (the task function: runs in any process).  Returns NumPy slices of the
    tile's texels: final, stderr, rel_stderr, converged, seen, and what the stitch needs for the
    warnings and the timing (history, seconds, peak RSS of this process)."""
    import drjit as dr

    with _ONE_AT_A_TIME:
        try:
            return _run_tile(task)
        finally:
            # Dr.Jit keeps freed blocks for reuse; tiles of other crop sizes one after the other in one
            # process would otherwise pile up blocks of every size (measured: a 256 x 256 map in 4 x 4 tiles,
            # peak RSS 3.6 GiB against 2.9 GiB for one tile of the same size)
            gc.collect()
            dr.flush_malloc_cache()


def _run_tile(task: Tile) -> dict:
    from hyde_bsdf.inverse.scalar import prepare

    prepare(task.capture.variant)
    observations = [Observation(task.capture.scene_of(j, i, crop), ref, sensor=0, mask=mask, measured=measured,
                                sigma=sigma) for j, i, crop, ref, measured, sigma, mask in task.crops]
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        res = invert_maps(observations, task.start, fit=task.fit, prefix=task.prefix, progress=False,
                          **task.options)
    r0, r1, c0, c1 = task.bounds
    cut = lambda a: np.array(np.asarray(a)[r0:r1, c0:c1])
    maps = lambda d: {n: cut(v) for n, v in d.items() if np.ndim(v) == 2}
    unc = res.uncertainty
    return {"index": task.index, "bounds": task.bounds, "final": maps(res.final), "stderr": maps(res.stderr),
            "rel_stderr": maps(res.rel_stderr), "converged": maps(res.converged), "seen": cut(res.seen),
            "unchecked": maps(unc.unchecked) if unc is not None else {},
            "step_se": maps(unc.step_se) if unc is not None else {},
            "filter_valid": unc.filter_valid if unc is not None else True,
            "messages": list(dict.fromkeys((w.category, str(w.message)) for w in caught
                                           if issubclass(w.category, UserWarning))),
            "history": res.history, "seconds_per_iteration": res.seconds_per_iteration,
            "first_iteration_seconds": res.first_iteration_seconds, "pixels": task.pixels,
            "peak_rss": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024}


def _concurrency(executor, workers) -> int:
    """How many tasks may run at once on this machine: ``workers`` when given; else 1 in process,
    the pool's size, or a dask cluster's threads (all of them when its scheduler is on this host, one
    worker's otherwise: each machine then holds its own)."""
    from hyde_bsdf.mom.solver import SerialExecutor

    if workers is not None:
        return int(workers)
    if executor is None or isinstance(executor, SerialExecutor):
        return 1
    if hasattr(executor, "_max_workers"):
        return int(executor._max_workers)
    from hyde_bsdf.mom.gather import scheduler_identity

    try:
        info = scheduler_identity(executor._client)
        threads = [int(w.get("nthreads", 1)) for w in info.get("workers", {}).values()] or [1]
        local = any(h in str(info.get("address", "")) for h in ("inproc", "127.0.0.1", "localhost"))
        return sum(threads) if local else max(threads)
    except Exception:  # noqa: BLE001 -- no scheduler to ask: assume one task at a time
        return 1


def _check_workers(workers):
    if workers is not None and (isinstance(workers, bool) or not isinstance(workers, (int, np.integer))
                                or workers < 1):
        raise UsageError(f"workers must be an integer >= 1 or None, got {workers!r}")


def invert_maps_tiled(capture: Capture, start: dict, *, fit=("alpha",), tiles=(2, 2), executor=None,
                      workers: int | None = None, prefix: str | None = None, truth: dict | None = None,
                      timeout: float | None = None, progress=True, **options) -> MapInversionResult:
    """:func:`~hyde_bsdf.inverse.maps.invert_maps` of a calibrated :class:`Capture`, in ``tiles`` =
    (rows, columns) of texels (or n: n x n), each an independent task (see the module docstring).

    ``executor``: None (``workers`` > 1: a :func:`~hyde_bsdf.mom.solver.process_pool` of that many,
    spawned, shut down after; else :class:`~hyde_bsdf.mom.solver.SerialExecutor`, in this process), or any
    ``concurrent.futures.Executor`` -- a dask cluster's ``client.get_executor()``, not the ``Client``
    itself (a one-line UsageError).  ``workers``: with an executor, how many tasks it runs at once on
    this machine, for the memory check (default: read from the executor).  ``timeout``: seconds
    without a finished tile after which the run stops (:func:`~hyde_bsdf.mom.gather.gather`).
    ``start``, ``fit``, ``prefix`` and ``options`` (iterations, lr, spp, seed, components,
    regularizer, weight, uncertainty, uncertainty_spp, polish, noise, threshold, convergence,
    extra_polish, freeze, average_last) go to every tile's :func:`invert_maps`.  The result is a
    :class:`MapInversionResult` of the whole map; ``result.tiles`` lists each tile's bounds, pixels,
    seconds per iteration and the peak RSS of the process that ran it; ``history`` holds the tiles'
    mean loss and their summed seconds (the work of one pass over all tiles)."""
    from hyde_bsdf.mom.gather import check_executor, end_pool, gather       # the executors (mom imports on demand)
    from hyde_bsdf.mom.solver import SerialExecutor, process_pool

    check_executor(executor)
    _check_workers(workers)
    if not isinstance(capture, Capture):
        raise UsageTypeError(f"capture must be a hyde_bsdf.inverse.tiles.Capture (Capture.from_files), got "
                             f"{type(capture).__name__}")
    bad = sorted(set(options) & {"seen", "truth", "progress", "observations"})
    if bad:
        raise UsageError(f"invert_maps_tiled: {', '.join(bad)} cannot be given per tile")
    from hyde_bsdf.inverse.scalar import prepare

    prepare(capture.variant)
    say = as_callback(progress, "[invert tiles]")
    t0 = time.perf_counter()
    tasks, shape, _ = plan_tiles(capture, start, fit=fit, tiles=tiles, prefix=prefix, options=options)
    if not tasks:
        raise UsageError("no picture has a whole pixel inside any tile: the sample is not seen (check the "
                         "`cameras`/`lights` files and the references' masks)")
    spp = int(options.get("spp", 4))
    unc_spp = int(options.get("uncertainty_spp", 16)) if options.get("uncertainty", True) else 0
    if workers is not None:
        workers = min(workers, len(tasks))          # 1000 workers for 4 tiles: 4 processes, 4 tiles at once
    largest, concurrent = max(t.pixels for t in tasks), min(_concurrency(executor, workers), len(tasks))
    estimate = check_memory(inversion_bytes(largest, spp, unc_spp) * concurrent,
                            f"{concurrent} tile(s) at once, the largest with {largest} px of film crops at {spp} spp",
                            "use more `tiles` (smaller crops), a lower `spp` or fewer `workers`")
    own = executor is None
    # spawned, not forked: a fork copies this process mid-work in Dr.Jit's (and a dask client's) threads,
    # and the children deadlock (measured: a forked pool after a dask LocalCluster in the same process)
    ex = (process_pool(workers, start_method="spawn") if workers and workers > 1 else SerialExecutor()) \
        if own else executor
    if say:
        say(f"{len(tasks)} tile task(s) of {shape[0]}x{shape[1]} texels, largest crop set "
            f"{max(t.pixels for t in tasks)} px, on {type(ex).__name__}")
    done = (lambda k: say(f"tile {k}/{len(tasks)} done ({time.perf_counter() - t0:.1f} s)")) if say else None
    results = None
    try:
        results = gather(ex, run_tile, tasks, timeout=timeout, on_done=done, heartbeat=bool(say), what="tile",
                         label="invert_maps_tiled")
    finally:
        if own:          # after a failure, no wait for a running tile: its worker is ended
            end_pool(ex, finished=results is not None)
    res = stitch_tiles(results, shape, start, tuple(fit), components=options.get("components", "stokes"),
                       threshold=options.get("threshold", STDERR_THRESHOLD),
                       convergence=options.get("convergence", CONVERGENCE_THRESHOLD),
                       regularized=bool(options.get("regularizer")) and options.get("weight", 0.0) > 0)
    res.truth = truth
    res.wall_seconds = time.perf_counter() - t0
    res.memory_estimate = estimate
    for category, message in res.messages:
        warnings.warn(message, category, stacklevel=2)
    return res


def _stitched(results, shape, key, fill, dtype=np.float64) -> dict:
    """{name: (rows, cols) map} of the tiles' ``key`` slices, ``fill`` elsewhere."""
    out = {}
    for r in results:
        r0, r1, c0, c1 = r["bounds"]
        for n, v in r[key].items():
            out.setdefault(n, np.full(shape, fill, dtype))[r0:r1, c0:c1] = v
    return out


def stitch_tiles(results, shape, start, fit, *, components="stokes", threshold=STDERR_THRESHOLD,
                 convergence=CONVERGENCE_THRESHOLD, regularized=False) -> MapInversionResult:
    """One :class:`MapInversionResult` from the tiles' :func:`run_tile` results: the maps (start values in
    the texels of no task), standard errors (NaN there), converged flags, the seen mask, the warnings
    recomputed over the whole map (identification and convergence) or said once (the others)."""
    from hyde_bsdf.inverse.uncertainty import (NotConvergedWarning, UnidentifiedParameterWarning,
                                               convergence_warnings)

    results = sorted(results, key=lambda r: r["index"])
    final = {n: np.array(np.broadcast_to(np.asarray(start[n], np.float64), shape)) for n in fit}
    for r in results:
        r0, r1, c0, c1 = r["bounds"]
        for n, v in r["final"].items():
            final[n][r0:r1, c0:c1] = v
    seen = np.zeros(shape, bool)
    for r in results:
        r0, r1, c0, c1 = r["bounds"]
        seen[r0:r1, c0:c1] = r["seen"]
    res = MapInversionResult(fitted=fit, final=final, start=dict(start), components=components, seen=seen)
    res.stderr, res.rel_stderr = _stitched(results, shape, "stderr", np.nan), _stitched(results, shape, "rel_stderr", np.nan)
    res.converged = _stitched(results, shape, "converged", False, bool)
    messages = []
    unchecked = _stitched(results, shape, "unchecked", np.nan)
    if unchecked:
        found = identification_warnings(unchecked, seen, threshold)
        messages += [(UnidentifiedParameterWarning, m) for _, m in found.values()]
        conv = convergence_warnings(res.converged, _stitched(results, shape, "step_se", np.nan), seen, convergence,
                                    regularized)
        messages += [(NotConvergedWarning, m) for _, m in conv.values()]
    redone = (UnidentifiedParameterWarning, NotConvergedWarning)
    messages += list(dict.fromkeys((c, m) for r in results for c, m in r["messages"] if not issubclass(c, redone)))
    res.messages = messages
    res.warnings = [m for _, m in messages]
    n_it = min(len(r["history"]) for r in results)
    res.history = [{"iteration": k, **{key: float(np.mean([r["history"][k][key] for r in results]))
                                       for key in ("loss", "data_loss", "regularizer")},
                    "seconds": float(sum(r["history"][k]["seconds"] for r in results))} for k in range(n_it)]
    res.seconds_per_iteration = float(sum(r["seconds_per_iteration"] for r in results))
    res.first_iteration_seconds = float(sum(r["first_iteration_seconds"] for r in results))
    res.tiles = [{k: r[k] for k in ("index", "bounds", "pixels", "seconds_per_iteration", "peak_rss")}
                 for r in results]
    return res
