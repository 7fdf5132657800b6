"""``hyde-bsdf invert``: the command line of scalar and texture-valued (``--maps``) inversion
(:mod:`hyde_bsdf.inverse`); the plot is :func:`hyde_bsdf.app.plots.plot_history`.

Errors: one line on stderr, exit 2; Ctrl-C: exit 130; progress per iteration on
stderr; output paths and memory checked before any rendering; outputs written atomically::

    hyde-bsdf invert [--scene SCENE.xml [--target PREFIX] | (built-in sphere)] [--truth rms_slope=0.3,eta=1.5,k=3]
                     [--reference REF.exr] [--start rms_slope=0.6,eta=3,k=6]
                     [--fit rms_slope,eta,k] [--loss stokes|s0] [--iterations 200]
                     [--spp 16] [--spp-ref 512] [--res 64] [--lr 0.05] [--seed 0] [-o OUTDIR]

writes OUTDIR/invert_history.csv and OUTDIR/invert.png (loss and parameter trajectories).
Texture mode::

    hyde-bsdf invert --maps [--scene S1.xml --reference R1.exr [--mask M1.png] ...
                     | --preset dielectric|metal [--noise 0.01]
                     | (built-in plane, 3 views x 2 lights, truth map of --map-size 32)]
                     [--fit alpha[,eta,k][,specular_reflectance]] [--start alpha=0.3,eta=1.6]
                     [--regularizer tv|l2 --weight 0.1] [--no-uncertainty]
                     [--iterations 100] [--spp 4] [--spp-ref 64] [--res 80] [--sensor 0] [-o OUTDIR]
    hyde-bsdf invert --maps --scene SAMPLE.xml --camera CAMERA.json --light LIGHT.json --reference R.exr ...
                     [--tiles N|RxC [--workers K | --scheduler tcp://HOST:8786]]

writes OUTDIR/invert_maps_history.csv, OUTDIR/NAME.npy and NAME.exr per fitted map (rows along
v; load the EXR as a ``bitmap`` texture with ``raw`` true and ``filter_type`` nearest; NaN where no
picture sees the texel), NAME_stderr.npy/.exr (per-texel standard errors; NaN where not valid),
NAME_seen.npy/.exr (1 where a picture sees the texel) and OUTDIR/invert_maps.png.  ``--preset`` captures the built-in synthetic sample
(:func:`hyde_bsdf.inverse.acquisition.example_material`) in the designed acquisition (:func:`hyde_bsdf.inverse.design_acquisition`; --res default
4 x --map-size, so that texels span pure pixels) and reports the errors against its truth.
"""
from __future__ import annotations

import math
import warnings
from pathlib import Path

import numpy as np

from hyde_bsdf.app.args import Parser, quiet_option, reads, run_inputs, user_input, writes
from hyde_bsdf.app.flags import for_command_line
from hyde_bsdf.app.plots import plot_history
from hyde_bsdf.errors import UsageError, one_line, shorten
from hyde_bsdf.inverse.acquisition import design_acquisition, example_material, synthetic_observations
from hyde_bsdf.inverse.loss import StokesLoss, as_mask, check_reference_scale, interior_mask
from hyde_bsdf.inverse.maps import invert_maps
from hyde_bsdf.inverse.observations import (LIGHTS, MAP_PARAMETERS, MAP_VARIANT, Observation, example_maps,
                                            map_keys, plane_scene_dict, render_stokes_np)
from hyde_bsdf.inverse.scalar import (PARAMETERS, RANGES, START, TRUTH, invert, load_scene, parameter_keys,
                                      prepare, render_reference)
from hyde_bsdf.io.atomic import atomic_path
from hyde_bsdf.io.input_gate import check_input
from hyde_bsdf.io.output_gate import check_free_space, check_output_path, output_gate
from hyde_bsdf.io.stokes_exr import exr_bytes
from hyde_bsdf.progress import stderr_lines
from hyde_bsdf.resources import COSTS, check_memory, inversion_bytes, wait_limit

__all__ = ["cli_main", "build_parser"]

_log = stderr_lines("[invert]")


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


def build_parser():
    ap = Parser(
        prog="hyde-bsdf invert",
        description="Recover the hyde BSDF's roughness and index from Stokes images by differentiable "
                    "rendering.  Scalar mode (default): rms_slope, eta, k (Mitsuba n + ik; the paper's "
                    "eta = n - jk, same numbers) from one image (llvm_ad_spectral_polarized).  --maps: a "
                    "texture-valued roughness (alpha or rms_slope bitmap), optionally index maps, from "
                    "one or more images (llvm_ad_mono_polarized).")
    ap.add_argument("--maps", action="store_true", help="texture-valued mode: fit per-texel maps")
    reads(ap.add_argument("--scene", action="append", default=None,
                    help="Mitsuba XML scene holding the BSDF (repeat for several scenes, e.g. one per light; "
                         "default: the built-in sphere (scalar) or textured plane, 3 views x 2 lights (--maps))"), "scene")
    reads(ap.add_argument("--reference", action="append", default=None,
                    help="reference Stokes EXR of the matching --scene (hyde-bsdf render or stokes output: "
                         "S0.R..S3.B or mono S0, S1, S2[, S3], with optional _sigma layers and mask; same film "
                         "size); default: render one at --truth (built-in truth map with --maps)"))
    reads(ap.add_argument("--mask", action="append", default=None,
                          help="--maps: PNG or .npy of the pixels to use for the matching --reference (non-zero = use)"))
    _calibrated_options(ap)
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
    ap.add_argument("--preset", default=None, choices=("dielectric", "metal"),
                    help="--maps: capture the built-in synthetic sample (an eta map; or n and k maps of a metal) in "
                         "the designed acquisition (5 mirror pairs at facet angles 10-70 deg + 2 off-specular "
                         "pairs; metal: a 45 deg polarizer on the light); --map-size texels, --res px per picture")
    ap.add_argument("--noise", type=float, default=0.01, help="--preset: camera noise added to the references, as a "
                    "fraction of the median S0 (default 0.01)")
    ap.add_argument("--no-uncertainty", action="store_true", help="--maps: skip the standard-error maps and the "
                    "Gauss-Newton polish (NAME_stderr.npy/.exr are written otherwise)")
    ap.add_argument("--lr", type=float, default=0.05, help="Adam learning rate (on log parameters)")
    ap.add_argument("--regularizer", default=None, choices=("tv", "l2"),
                    help="--maps: smoothness term on each fitted map (total variation or squared gradient)")
    ap.add_argument("--weight", type=float, default=0.0, help="--maps: regulariser weight lambda (loss units "
                    "per map unit (tv) or squared map unit (l2); 0.1 mild, >= 1 flattens; default 0)")
    ap.add_argument("--seed", type=int, default=0, help="random seed (integer >= 0)")
    writes(ap.add_argument("-o", "--output", default="out/invert", help="output folder (default out/invert)"))
    quiet_option(ap)
    return ap


def _calibrated_options(ap):
    """--camera, --light (the calibrated rig), --tiles, --workers, --scheduler (tiles as tasks), --channel."""
    reads(ap.add_argument("--camera", default=None, help="--maps: camera calibration JSON (CV pinhole: world-to-camera R, t; "
                    "fx, fy, cx, cy; see hyde_bsdf.render.camera): the sensors of the one --scene (the sample only)"))
    reads(ap.add_argument("--light", default=None, help="--maps with --camera: light JSON (point positions or directional "
                    "towards_light, optional polarizer/retarder); one scene per light, --reference light-major"))
    ap.add_argument("--tiles", default=None, help="--maps with --camera: split the map into tiles of texels, N (N x N) "
                    "or RxC, each fitted from the film crop of the pixels wholly inside it, as an independent task "
                    "(memory: the largest tile's crop instead of the whole picture; see hyde_bsdf.inverse.tiles)")
    ap.add_argument("--workers", type=int, default=None, help="--tiles: run the tiles in a process pool of this many "
                    "workers on this machine (default: one tile after the other in this process)")
    ap.add_argument("--scheduler", default=None, help="--tiles: run the tiles on the dask cluster whose scheduler is "
                    "at this address (tcp://HOST:8786; needs the distributed extra; start its workers with "
                    "--nthreads 1: one tile per process at a time)")
    ap.add_argument("--channel", default="Y", help="--maps: the colour channel of multi-channel references (default "
                    "Y, the luminance of R, G, B; or a channel suffix such as R or 550nm)")


def _check_args(args):
    maps = args.maps
    d = {"iterations": 100 if maps else 200, "spp": 4 if maps else 16, "spp_ref": 64 if maps else 512,
         "res": (4 * args.map_size if args.preset else 80) if maps else 64}
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
    if (args.camera is None) != (args.light is None):
        raise UsageError("--camera and --light go together (the calibrated sensors and the lights)")
    if args.camera and not (maps and len(scenes) == 1 and refs and not args.preset):
        raise UsageError("--camera/--light need --maps, one --scene (the sample: shapes, BSDF, integrator) and the "
                         "--reference files, light-major")
    for path in [p for p in (args.camera, args.light) if p]:
        check_input(path, "--camera/--light file", stdin=False)
    if refs and len(refs) != max(1, len(scenes)) and not args.camera:
        raise UsageError(f"give one --reference per --scene: {len(scenes)} --scene, {len(refs)} --reference")
    if maps and scenes and not refs:
        raise UsageError("--maps with --scene needs a --reference per scene (the truth maps of a user scene "
                         "are unknown)")
    if not maps and len(scenes) > 1:
        raise UsageError("scalar mode takes one --scene; several scenes need --maps")
    if masks and len(masks) != len(refs):
        raise UsageError(f"give one --mask per --reference: {len(refs)} --reference, {len(masks)} --mask")
    for path in scenes + refs + masks:       # the input gate: regular files (no FIFO, no device)
        check_input(path, "input file", stdin=False)
    if args.truth is not None and refs:
        pass                                   # errors are reported against it
    _check_tiles_args(args)
    if (args.preset or args.no_uncertainty) and not maps:
        raise UsageError("--preset and --no-uncertainty need --maps")
    if not (math.isfinite(args.noise) and 0 <= args.noise <= 1):
        raise UsageError(f"--noise must be a fraction in [0, 1], got {args.noise}")
    if maps and args.truth is not None:
        raise UsageError("--truth is for scalar mode; --maps renders its references from the built-in "
                         "truth map or reads --reference")


def _check_tiles_args(args):
    """--tiles N or RxC (with --camera), --workers K >= 1 or --scheduler ADDRESS (with --tiles, not both)."""
    if args.tiles is None:
        if args.workers is not None or args.scheduler is not None:
            raise UsageError("--workers and --scheduler run tiles: give --tiles N (or RxC) too")
        return
    if not args.camera:
        raise UsageError("--tiles needs --maps --scene SAMPLE.xml --camera CAMERA.json --light LIGHT.json (the tasks "
                         "rebuild the calibrated scenes from these files)")
    parts = args.tiles.lower().split("x")
    if len(parts) > 2 or not all(p.strip().isdigit() and int(p) >= 1 for p in parts):
        raise UsageError(f"--tiles must be N or RxC with integers >= 1 (e.g. 4 or 4x8), got {shorten(args.tiles)}")
    args.tile_grid = (int(parts[0]), int(parts[-1]))
    if args.scene:
        _check_tile_grid(args.tile_grid, args.scene[0], args.reference or [])
    if args.workers is not None and args.workers < 1:
        raise UsageError(f"--workers must be an integer >= 1, got {args.workers}")
    if args.workers is not None and args.scheduler is not None:
        raise UsageError("give --workers (a process pool here) or --scheduler (a dask cluster), not both")


def _check_tile_grid(grid, scene, references) -> None:
    """--tiles RxC refused before any scene loads when it is finer than the data, from what the files'
    headers say: when no texture of the scene's file graph has R rows and C columns of texels (the map
    is one of them; each tile needs a texel; a texture whose header cannot be read is refused here),
    and -- whatever the textures are, files or not -- when the R x C tiles outnumber the pixels of the
    --reference pictures (each tile needs a whole pixel of its own)."""
    from hyde_bsdf.errors import InputFileError
    from hyde_bsdf.io.arrays import exr_shape, image_shape
    from hyde_bsdf.io.scene_files import scene_files

    sizes = {p: image_shape(p, "scene texture") for p in scene_files(scene)[1:] if p.is_file()}
    sizes = {p: s for p, s in sizes.items() if s is not None}
    if sizes and not any(h >= grid[0] and w >= grid[1] for h, w, *_ in sizes.values()):
        biggest = max(sizes, key=lambda p: sizes[p][0] * sizes[p][1])
        h, w = sizes[biggest][:2]
        raise UsageError(f"--tiles must be 1..{h} x 1..{w} for a {h} x {w}-texel map, got {grid[0]} x {grid[1]} "
                         f"(the scene's largest texture, {shorten(biggest.name)}, read before any scene loads)")
    try:
        pixels = sum(math.prod(exr_shape(r, "--reference")[:2]) for r in references)
    except InputFileError:
        return                          # refused, with its reason, when the references are read
    if references and grid[0] * grid[1] > pixels:
        raise UsageError(f"--tiles {grid[0]}x{grid[1]} makes {grid[0] * grid[1]} tiles, more than the {pixels} pixels "
                         f"of the {len(references)} --reference picture(s): each tile needs a whole pixel of its own; "
                         "use fewer tiles")


#: invert_maps' default samples per pixel of the uncertainty step (its forward-mode renders; memory check)
UNCERTAINTY_SPP = 16
def _check_map_memory(args, fit):
    """--map-size checked against the available memory before any map is allocated."""
    if args.scene:
        return                          # a user scene's textures: their size is the scene's
    per_texel = COSTS.map_bytes_per_texel_fixed + COSTS.map_bytes_per_texel_fitted * len(fit)
    check_memory(per_texel * args.map_size ** 2, f"the {args.map_size}x{args.map_size} maps "
                 f"({per_texel} B per texel)", "lower --map-size")


def _check_step_memory(width, height, args, remedy, uncertainty_spp=0):
    """One optimisation step on a ``width`` x ``height`` film (and the uncertainty step's renders)
    checked against the available memory before the scenes render (:func:`~hyde_bsdf.resources.inversion_bytes`)."""
    need = inversion_bytes(width * height, args.spp, uncertainty_spp)
    also = f" (and the uncertainty step at {uncertainty_spp} spp)" if uncertainty_spp else ""
    check_memory(need, f"one optimisation step on the {width}x{height} film at {args.spp} spp{also}",
                 f"lower {remedy}")


def _history_bytes(args) -> int:
    """Upper bound of a history CSV: a header and a row per iteration."""
    return COSTS.history_row_bytes * (args.iterations + 1)


def _maps_bytes(args, fit, shape) -> int:
    """Upper bound of what ``--maps`` writes for maps of ``shape`` (rows, columns): for each fitted
    name its map, its seen map and (without --no-uncertainty) its standard-error map, each a
    float32 ``.npy`` (128-byte header) and a one-channel ``.exr``; the history CSV; the plot."""
    rows, cols = shape
    per_map = 4 * rows * cols + 128 + exr_bytes(cols, rows, 1)
    return len(fit) * (2 if args.no_uncertainty else 3) * per_map + _history_bytes(args) + COSTS.plot_file_bytes


def _scene_map_shape(observations, fit, args) -> tuple[int, int]:
    """The largest (rows, columns) of the fitted textures of the first --scene (1 x 1 for a constant)."""
    import mitsuba as mi

    params = mi.traverse(observations[0].scene)
    shapes = [tuple(params[k].shape[:2]) if k.endswith(".data") else (1, 1)
              for k in map_keys(params, fit, args.target).values()]
    return max(shapes, key=lambda s: s[0] * s[1])


def _run_inputs(args) -> list:
    """Every file this run reads (:func:`~hyde_bsdf.app.args.run_inputs`), which no output may replace."""
    return run_inputs(build_parser(), args)


def _check_out(path):
    """An output file checked writable before any long work (a UsageError naming -o otherwise)."""
    with user_input():
        return check_output_path(path, "-o/--output file")


def _read_reference(path, width, height, what="--reference"):
    """Luminance Stokes images (4, H, W) of a Stokes EXR, read as every reference is
    (:func:`~hyde_bsdf.inverse.camera_data.camera_reference`), checked against the film size, for all
    four components (the scalar inversion compares S0..S3) and for NaN."""
    from hyde_bsdf.inverse.camera_data import camera_reference

    _check_reference_size(path, width, height, what)
    with user_input(f"{what} {shorten(str(path))}", library=True):
        data = camera_reference(str(path), channel="Y")       # (warns about pixels no light gives: mask 0)
    if len(data["measured"]) < 4:
        raise UsageError(f"{what} {shorten(str(path))} holds {'+'.join(data['measured'])}; the scalar inversion "
                         "compares all four Stokes components (S0..S3): use --maps for a camera's measured ones")
    ref = data["reference"]
    h, w = ref.shape[1:]
    if (w, h) != (width, height):
        raise UsageError(f"{what} {str(path)!r} is {w}x{h} pixels but the scene's film is {width}x{height}: "
                         f"render the reference with the same scene and film")
    with user_input():
        check_reference_scale(ref, f"{what} {str(path)!r}")
    return ref, data["mask"]


def _check_reference_size(path, width, height, what="--reference") -> None:
    """The reference's size against the film, from its header: before its data are read (and warned about)."""
    from hyde_bsdf.io.arrays import exr_shape

    h, w = exr_shape(check_input(path, what, stdin=False), what)[:2]
    if (w, h) != (width, height):
        raise UsageError(f"{what} {shorten(str(path))} is {w}x{h} pixels but the scene's film is "
                         f"{width}x{height}: render the reference with the same scene and film")


def _camera_observation(scene, args, path, width, height, mask):
    """The observation of a user --reference: any camera Stokes EXR (measured components, sigma, mask;
    :func:`hyde_bsdf.inverse.camera_data.camera_observation`), checked against the film size."""
    from hyde_bsdf.inverse.camera_data import camera_observation

    _check_reference_size(path, width, height)
    o = camera_observation(scene, path, sensor=args.sensor, mask=None, channel=args.channel)
    h, w = o.reference.shape[1:]
    if (w, h) != (width, height):
        raise UsageError(f"--reference {shorten(str(path))} is {w}x{h} pixels but the scene's film is "
                         f"{width}x{height}: render the reference with the same scene and film")
    with user_input():
        check_reference_scale(o.reference, f"--reference {shorten(str(path))}")
    if mask is not None:
        o.mask = o.mask & mask
    return o


def _calibrated(args, fit):
    """The observations of --scene SAMPLE --camera --light --reference ... (light-major), checked."""
    import mitsuba as mi

    from hyde_bsdf.inverse.camera_data import observations_from_files

    observations = observations_from_files(args.scene[0], args.camera, args.light, args.reference,
                                           spp=args.spp, channel=args.channel)
    for k, o in enumerate(observations):
        with user_input(f"--scene {shorten(args.scene[0])}"):
            map_keys(mi.traverse(o.scene), fit, args.target)
        H, W = o.reference.shape[1:]
        _check_step_memory(W, H, args, "--tiles N (fit tiles of the map from film crops), --spp or the camera's "
                           "width/height", uncertainty_spp=0 if args.no_uncertainty else UNCERTAINTY_SPP)
        with user_input():
            check_reference_scale(o.reference, f"--reference {shorten(args.reference[k])}")
        if args.mask:
            o.mask = o.mask & _read_mask(args.mask[k], (H, W))
    _log(f"{len(observations)} calibrated picture(s): measured {'+'.join(observations[0].measured)}"
         f"{', with sigma maps' if observations[0].sigma is not None else ''}")
    return observations


def _read_mask(path, shape):
    """The --mask file (PNG, TIFF or .npy; sized from its header first) as booleans of ``shape``."""
    from hyde_bsdf.io.arrays import array_header, read_array

    size = array_header(path, "--mask")[0][:2]
    if size != tuple(shape):
        raise UsageError(f"--mask {str(path)!r} is {size[1]}x{size[0]} pixels but the film is "
                         f"{shape[1]}x{shape[0]}")
    m = read_array(path, "--mask")
    return as_mask(m[..., :3].max(axis=2) if m.ndim == 3 else m, f"--mask {shorten(str(path))}")


def _load_user_scene(path):
    try:
        return load_scene(path)
    except (RuntimeError, ValueError) as exc:
        raise UsageError(f"--scene {str(path)!r}: Mitsuba could not load it: {one_line(exc)[:400]}") from None


def cli_main(argv=None) -> int:
    """``hyde-bsdf invert``: 0 on success; user errors raise UsageError, a diverging run
    FloatingPointError (with a hint), Ctrl-C KeyboardInterrupt -- :func:`hyde_bsdf.app.cli.main`
    turns each into one line and an exit status.  Progress per iteration on stderr."""
    try:
        return _cli(argv)
    except FloatingPointError as exc:
        raise FloatingPointError(f"{one_line(exc)} (try a smaller --lr or more --spp)") from exc


def _cli(argv):
    args = build_parser().parse_args(argv)
    _check_args(args)
    if args.maps:
        return _cli_maps(args)
    truth = {**TRUTH, **_parse_values(args.truth or "", "--truth")}
    start = {**START, **_parse_values(args.start or "", "--start")}
    fit = tuple(s.strip() for s in (",".join(PARAMETERS) if args.fit is None else args.fit).split(",") if s.strip())
    bad = [p for p in fit if p not in PARAMETERS]
    if bad or not fit:
        raise UsageError(f"--fit must list parameters from {', '.join(PARAMETERS)}, got {args.fit!r}")
    out = Path(args.output)
    paths = [_check_out(out / name) for name in ("invert_history.csv", "invert.png")]
    with output_gate(paths, inputs=_run_inputs(args), need_bytes=_history_bytes(args) + COSTS.plot_file_bytes,
                     what="-o/--output file"):
        return _scalar_run(args, truth, start, fit, paths)


def _scalar_run(args, truth, start, fit, paths):
    try:
        prepare()
    except RuntimeError as exc:
        raise UsageError(one_line(exc)) from None
    import mitsuba as mi

    scene = (load_scene(None, res=args.res, spp=args.spp) if not args.scene else _load_user_scene(args.scene[0]))
    with user_input():
        parameter_keys(mi.traverse(scene), PARAMETERS, args.target)   # exactly one hyde BSDF, or a clear error
    W, H = scene.sensors()[0].film().crop_size()
    _check_step_memory(W, H, args, "--spp" + (" or --res" if not args.scene else " or the film's width/height"))
    mask = None
    if args.reference:
        ref, good = _read_reference(args.reference[0], W, H)
        truth_known = args.truth is not None
        mask = None if good is None else interior_mask(ref[0]) & good      # pixels no light gives: left out
    else:
        _log(f"rendering the reference at {truth} ({args.spp_ref} spp)")
        ref = render_reference(scene, truth, args.spp_ref, seed=args.seed, prefix=args.target)
        truth_known = True
    with user_input("--reference"):
        loss_fn = StokesLoss(ref, mask=mask, components=args.loss)
    with warnings.catch_warnings(record=True) as caught:      # printed once each below, as WARNING: lines
        warnings.simplefilter("always")
        res = invert(scene, loss_fn, start, fit=fit, iterations=args.iterations, lr=args.lr, spp=args.spp,
                     seed=args.seed, truth=truth if truth_known else None, prefix=args.target)
    res.write_history(paths[0])
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
    for message in dict.fromkeys(res.warnings + [str(w.message) for w in caught]):
        print(f"WARNING: {for_command_line(message)}")
    print(f"wrote {paths[0]} and {paths[1]}")
    return 0


def _maps_fit_and_start(args):
    """The fitted map names and their start values, from --fit, --preset and --start."""
    names = tuple(MAP_PARAMETERS)
    ranges = {n: MAP_PARAMETERS[n][1] for n in names}
    preset_fit = {"dielectric": "alpha,eta", "metal": "alpha,eta,k"}
    text = preset_fit.get(args.preset, "alpha") if args.fit is None else args.fit      # "" is no parameter, not the default
    fit = tuple(s.strip() for s in text.split(",") if s.strip())
    bad = [p for p in fit if p not in names]
    if bad or not fit:
        raise UsageError(f"--fit must list parameters from {', '.join(names)}, got {shorten(args.fit)}")
    if "alpha" in fit and "rms_slope" in fit:
        raise UsageError("--fit: alpha and rms_slope are the same roughness; fit one of them")
    start = {n: 0.3 for n in fit if n in ("alpha", "rms_slope")}
    if args.preset:             # constant start maps away from the built-in sample's values
        start.update({"eta": 1.6 if args.preset == "dielectric" else 0.8, "k": 4.0, "specular_reflectance": 1.0})
        start = {n: v for n, v in start.items() if n in fit}
    elif "specular_reflectance" in fit:
        start["specular_reflectance"] = 1.0
    start.update(_parse_values(args.start or "", "--start", names, ranges))
    missing = [n for n in fit if n not in start]
    if missing:
        raise UsageError(f"--start must give a start value for {', '.join(missing)} (e.g. --start "
                         f"{','.join(f'{n}=1.5' for n in missing)})")
    return fit, start


def _maps_outputs(args, fit) -> dict:
    """Every file the maps mode writes, checked before any work: {key: path}."""
    out = Path(args.output)
    outputs = {"history": "invert_maps_history.csv", "png": "invert_maps.png"}
    for n in fit:
        outputs[n + ".npy"] = f"{n}.npy"
        outputs[n + ".exr"] = f"{n}.exr"
        outputs[n + "_seen.npy"] = f"{n}_seen.npy"
        outputs[n + "_seen.exr"] = f"{n}_seen.exr"
        if not args.no_uncertainty:
            outputs[n + "_stderr.npy"] = f"{n}_stderr.npy"
            outputs[n + "_stderr.exr"] = f"{n}_stderr.exr"
    return {k: _check_out(out / v) for k, v in outputs.items()}


def _preset_observations(args, fit, start):
    """--preset: the built-in sample captured in the designed acquisition; (observations, truth)."""
    if args.scene:
        raise UsageError("--preset renders the built-in sample; with --scene give the references of your own "
                         "acquisition instead")
    if "rms_slope" in fit or ("k" in fit and args.preset == "dielectric"):
        raise UsageError(f"--fit: the {args.preset} preset fits alpha, eta"
                         f"{', k' if args.preset == 'metal' else ''} and specular_reflectance; got {shorten(args.fit)}")
    material = example_material(args.preset, args.map_size)
    if "specular_reflectance" not in fit:
        material["specular_reflectance"] = 1.0
    truth = {n: np.asarray(material[n], float) for n in fit}
    acq = design_acquisition(args.preset)
    _check_step_memory(args.res, args.res, args, "--spp or --res")
    _log(f"{args.preset} preset: {len(acq.configurations)} pictures of {args.res}x{args.res} px "
         f"({acq.polarized()} behind a polarizer), references at {args.spp_ref} spp + {100 * args.noise:g} % noise")
    observations = synthetic_observations(acq, material, start, res=args.res, spp=args.spp, spp_ref=args.spp_ref,
                                          noise=args.noise, seed=args.seed)
    return observations, truth


def _scene_observations(args, fit):
    """--scene (the user's) or the built-in textured plane: (observations, truth or None)."""
    import mitsuba as mi

    truth = None
    if args.camera:
        return _calibrated(args, fit), truth
    if args.scene:
        scenes = _load_map_scenes(args.scene, fit)
    else:
        if fit != ("alpha",):
            raise UsageError("the built-in --maps scene has a known index (eta 1.5, k 3) and an alpha map: "
                             "--fit alpha (give --scene/--reference for other fits)")
        truth_map = example_maps(args.map_size)
        truth = {"alpha": truth_map}
        scenes = [mi.load_dict(plane_scene_dict(truth_map, light=j, res=args.res, spp=args.spp))
                  for j in range(len(LIGHTS))]
    observations = []
    for i, scene in enumerate(scenes):
        if args.sensor >= len(scene.sensors()):
            raise UsageError(f"--sensor {args.sensor}: scene {i} has {len(scene.sensors())} sensor(s)")
        with user_input(f"scene {i}"):
            map_keys(mi.traverse(scene), fit, args.target)
        W, H = scene.sensors()[args.sensor].film().crop_size()
        _check_step_memory(W, H, args, "--spp" + (" or --res" if not args.scene else " or the film's width/height"))
        mask = _read_mask(args.mask[i], (H, W)) if args.mask else None
        if args.reference:
            observations.append(_camera_observation(scene, args, args.reference[i], W, H, mask))
            continue
        _log(f"rendering reference {i + 1}/{len(scenes)} ({args.spp_ref} spp)")
        ref = render_stokes_np(scene, args.sensor, args.spp_ref, seed=args.seed)
        observations.append(Observation(scene, ref, sensor=args.sensor, mask=mask))
    return observations, truth


def _print_maps_result(res, args, fit, start, n_images, paths, messages) -> None:
    print(f"loss: {args.loss}; {args.iterations} iterations over {n_images} image(s), "
          f"{res.seconds_per_iteration:.3f} s/iteration (first {res.first_iteration_seconds:.1f} s incl. JIT)")
    for n in fit:
        v = np.asarray(res.final[n])
        line = f"  {n:9s} start {start[n]:.4g} -> "
        line += (_map_range(res, n) if v.ndim == 2 else f"{float(v):.5g}")
        if res.truth and n in res.truth:
            e = res.texel_errors(n)
            line += (f"; per-texel error over the {int(res.seen.sum())} seen texels: median "
                     f"{100 * np.median(e):.2f} %, 90th percentile {100 * np.percentile(e, 90):.2f} %")
        print(line)
        if n in res.rel_stderr:
            rel = res.rel_stderr[n][res.seen] if res.seen is not None else res.rel_stderr[n].ravel()
            rel = rel[~np.isnan(rel)]            # NaN: no whole pixel, not converged, bilinear: said in the warnings
            if rel.size:
                print(f"  {'':9s} relative standard error: median {100 * np.median(rel):.3g} %, 90th percentile "
                      f"{100 * np.percentile(rel, 90):.3g} %")
    if res.seen is not None:
        print(f"  texels seen by the images: {int(res.seen.sum())} of {res.seen.size}")
    for message in messages:
        print(f"WARNING: {for_command_line(message)}")
    print("wrote " + ", ".join(str(p) for p in paths.values()))


def _cli_maps(args):
    """``hyde-bsdf invert --maps``: check, gather the observations, invert, write, report."""
    fit, start = _maps_fit_and_start(args)
    paths = _maps_outputs(args, fit)
    _check_map_memory(args, fit)
    # the maps' size: --map-size's, or (--scene) the scene's textures', checked once they are loaded
    need = 0 if args.scene else _maps_bytes(args, fit, (args.map_size, args.map_size))
    with output_gate(list(paths.values()), inputs=_run_inputs(args), need_bytes=need, what="-o/--output file"):
        return _maps_run(args, fit, start, paths)


def _maps_run(args, fit, start, paths):
    """The --maps run inside the output gate: observations, inversion, outputs, summary."""
    try:
        prepare(MAP_VARIANT)
    except RuntimeError as exc:
        raise UsageError(one_line(exc)) from None
    if args.tiles:
        return _tiled_run(args, fit, start, paths)
    if args.preset:
        observations, truth = _preset_observations(args, fit, start)
    else:
        observations, truth = _scene_observations(args, fit)
    if args.scene:       # the free space for the scene's maps, before the inversion
        shape = _scene_map_shape(observations, fit, args)
        check_free_space(Path(args.output), _maps_bytes(args, fit, shape),
                         f"-o/--output {shorten(args.output)} ({shape[0]}x{shape[1]} maps)")
    # the library's warnings are recorded and printed once each in the summary (as WARNING: lines),
    # not also by Python's warning display; the inputs (masks, start shapes) found inconsistent: UsageError
    with user_input(), warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        res = invert_maps(observations, start, fit=fit, iterations=args.iterations, lr=args.lr, spp=args.spp,
                          seed=args.seed, components=args.loss, regularizer=args.regularizer, weight=args.weight,
                          truth=truth, prefix=args.target, uncertainty=not args.no_uncertainty)
    messages = list(dict.fromkeys(res.warnings + [str(w.message) for w in caught
                                                  if issubclass(w.category, UserWarning)]))
    _write_map_outputs(res, paths, args)
    _print_maps_result(res, args, fit, start, len(observations), paths, messages)
    return 0


def _tiled_run(args, fit, start, paths):
    """--tiles: the calibrated capture (files read and checked here), the tiles on the chosen executor,
    the stitched maps written and reported as the untiled run's."""
    from hyde_bsdf.inverse.tiles import Capture, invert_maps_tiled

    client = _dask_client(args.scheduler) if args.scheduler else None     # before the work: a dead address
    try:
        capture = Capture.from_files(args.scene[0], args.camera, args.light, args.reference, channel=args.channel,
                                     spp=args.spp)
        for k, d in enumerate(r for row in capture.references for r in row):
            with user_input():
                check_reference_scale(d["reference"], f"--reference {shorten(args.reference[k])}")
            if args.mask:
                m = _read_mask(args.mask[k], d["reference"].shape[1:])
                d["mask"] = m if d["mask"] is None else d["mask"] & m
        with user_input(), warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            res = invert_maps_tiled(capture, start, fit=fit, tiles=args.tile_grid, workers=args.workers,
                                    executor=None if client is None else client.get_executor(), prefix=args.target,
                                    iterations=args.iterations, lr=args.lr, spp=args.spp, seed=args.seed,
                                    components=args.loss, regularizer=args.regularizer, weight=args.weight,
                                    uncertainty=not args.no_uncertainty)
    finally:
        if client is not None:
            client.close(timeout=wait_limit("connect")[0])
    messages = list(dict.fromkeys(res.warnings + [str(w.message) for w in caught
                                                  if issubclass(w.category, UserWarning)]))
    _write_map_outputs(res, paths, args)
    _print_maps_result(res, args, fit, start, len(args.reference), paths, messages)
    print(f"tiles: {len(res.tiles)} task(s) of {args.tile_grid[0]}x{args.tile_grid[1]}, {res.wall_seconds:.1f} s in all, "
          f"peak RSS of a task's process {max(t['peak_rss'] for t in res.tiles) / 2**30:.2f} GiB")
    return 0


def _dask_client(address):
    """A dask.distributed Client of the scheduler at --scheduler ADDRESS, connected within
    HYDE_BSDF_CONNECT_TIMEOUT seconds (a UsageError naming it otherwise).  The connection is made
    in a thread of its own: a peer that accepts and never answers holds that thread, not the run."""
    import threading

    try:
        from distributed import Client
    except ImportError:
        raise UsageError("--scheduler needs dask.distributed: pip install 'hyde-bsdf[distributed]'") from None
    seconds, name = wait_limit("connect")
    box = {}

    def connect():
        try:
            box["client"] = Client(address, timeout=seconds, set_as_default=False)
        except Exception as exc:  # noqa: BLE001 -- reported below
            box["error"] = exc

    thread = threading.Thread(target=connect, name="dask-connect", daemon=True)
    thread.start()
    thread.join(seconds + 1.0)
    if "client" in box:
        return box["client"]
    why, error = f"no answer within {seconds:g} s ({name})", box.get("error")
    if error is not None:          # dask's own time-out (a port that never completes a handshake), a reset, noise
        why = (f"{why}: {one_line(error)}" if "timed out" in str(error).lower() else
               f"its answer is not dask's protocol: {one_line(error)}" if isinstance(error, (MemoryError, ValueError))
               else one_line(error))           # (dask reads a length from the noise and allocates it)
    raise UsageError(f"--scheduler {shorten(address)}: no dask scheduler answers there ({why})")


def _load_map_scenes(paths, fit) -> list:
    """The --scene files, their fitted bitmaps loaded with filter_type nearest (the per-texel
    standard errors assume it; one WARNING naming the maps that filtered bilinearly) and Mitsuba's
    per-scene 'Monochrome mode enabled' said once."""
    from hyde_bsdf.mitsuba.log import log_once
    from hyde_bsdf.render.renderer import load_scene_nearest

    scenes, changed = [], []
    with log_once():
        for p in paths:
            try:
                scene, names = load_scene_nearest(p, fit)
            except (RuntimeError, ValueError) as exc:
                raise UsageError(f"--scene {shorten(str(p))}: Mitsuba could not load it: {one_line(exc)}") from None
            scenes.append(scene)
            changed += [n for n in names if n not in changed]
    if changed:
        print(f"WARNING: the bitmap(s) of {', '.join(changed)} filter bilinearly (Mitsuba's default); they are "
              "fitted with filter_type nearest, which the per-texel standard errors assume -- write "
              "<string name=\"filter_type\" value=\"nearest\"/> in the scene to render what was fitted")
    return scenes


def _map_range(res, n) -> str:
    """'map WxH, min..max (median m) over K of N texels with a valid standard error' (the texels
    without one -- unseen, not converged, no whole pixel -- are not results)."""
    v = np.asarray(res.final[n])
    ok = res.valid(n)
    if not ok.any():
        return f"map {v.shape[1]}x{v.shape[0]}, no texel with a valid standard error"
    w = v[ok]
    what = "with a valid standard error" if n in res.rel_stderr else "seen"
    return (f"map {v.shape[1]}x{v.shape[0]}, {w.min():.4g}..{w.max():.4g} (median {np.median(w):.4g}) over "
            f"{int(ok.sum())} of {ok.size} texels {what}")


def _write_map_outputs(res, paths, args):
    res.write_history(paths["history"])
    for n in res.fitted:
        v = np.asarray(res.final[n], np.float32)
        if v.ndim == 2 and res.seen is not None:      # an unseen texel keeps no start value: NaN
            v = np.where(res.seen, v, np.nan).astype(np.float32)
        seen = (np.asarray(res.seen, np.float32) if res.seen is not None and v.ndim == 2
                else np.ones(np.shape(v) or (1, 1), np.float32))
        _save_map(paths, n + "_seen", seen)
        _save_map(paths, n, v if v.ndim == 2 else np.full((1, 1), v, np.float32), npy=v)
        if n + "_stderr.npy" in paths and n in res.stderr:
            _save_map(paths, n + "_stderr", np.asarray(res.stderr[n], np.float32))
    _plot_maps(res, paths["png"], args.loss)


def _save_map(paths, key, image, npy=None):
    """One map as ``KEY.npy`` (``npy`` if given, else ``image``) and a one-channel ``KEY.exr``."""
    import mitsuba as mi

    with atomic_path(paths[key + ".npy"]) as tmp:
        with open(tmp, "wb") as fh:
            np.save(fh, image if npy is None else npy)
    with atomic_path(paths[key + ".exr"]) as tmp:
        mi.Bitmap(image[..., None]).write(str(tmp))


def _plot_maps(res, path, loss):
    """The recovered maps (and their error against the truth, where known) and the loss curve."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    maps = [n for n in res.fitted if np.ndim(res.final[n]) == 2]
    cols = 1 + sum(2 if res.truth and n in res.truth else 1 for n in maps)
    fig, axes = plt.subplots(1, max(cols, 2), figsize=(4.2 * max(cols, 2), 3.6), layout="constrained")
    c = 0
    for n in maps:
        shown = np.where(res.seen, res.final[n], np.nan) if res.seen is not None else res.final[n]
        im = axes[c].imshow(shown, origin="lower", extent=(0, 1, 0, 1))
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
    axes[c].set_title(f"loss ({loss})")
    with atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=100, format="png")
    plt.close(fig)
