"""``hyde-bsdf stokes``: raw analyzer frames -> a Stokes EXR with per-component sigma and a mask, plus
intensity, DoLP and AoLP charts (:mod:`hyde_bsdf.model.polarimetry`).

    hyde-bsdf stokes (--mosaic RAW [--layout 90,45,135,0] [--demosaic superpixel|bilinear]
                      | --frames F1 F2 F3 [...] --angles 0,45,90[,...] [--retarder FAST,RETARDANCE])
                     [--analysis A.npy] [--gain 1] [--read-noise 0] [--full-well inf] [--black-level 0]
                     [--dn-per-unit 1] [--saturated error|mask] -o OUT.exr [--png STEM]

Frames: ``.npy`` arrays (H, W) or (H, W, C), or 8/16-bit grey PNG/TIFF images, raw DN with the black
level in them.  ``--retarder`` puts a retarder (fast axis, retardance in deg) in front of every
frame; a mixed rig needs ``--analysis`` (an (N, 4) or (H, W, N, 4) matrix in a ``.npy``).  The EXR
is what ``hyde-bsdf invert --maps --reference`` reads.  Errors: one line, exit 2.
"""
from __future__ import annotations

import math
import sys
from pathlib import Path

import numpy as np

from hyde_bsdf.app.args import Parser, quiet_option, reads, run_inputs, writes
from hyde_bsdf.errors import UsageError, shorten

__all__ = ["build_parser", "cli_main", "read_frame"]


def build_parser():
    ap = Parser(prog="hyde-bsdf stokes", description="Stokes images (S0, S1, S2[, S3]) with per-component "
                 "standard deviations from raw analyzer frames: N >= 3 frames at known analyzer angles, or one "
                 "division-of-focal-plane mosaic.  Least squares through the analysis matrix; the camera's "
                 "noise (gain, read noise) propagated to sigma.")
    src = ap.add_mutually_exclusive_group(required=True)
    reads(src.add_argument("--mosaic", help="one DoFP raw mosaic (.npy, PNG or TIFF; H, W even)"))
    reads(src.add_argument("--frames", nargs="+", help="N >= 3 raw frames behind analyzers at --angles"))
    ap.add_argument("--angles", help="analyzer angles of --frames in deg, comma-separated (counter-clockwise "
                    "from image right towards image up)")
    ap.add_argument("--layout", default="90,45,135,0", help="--mosaic: analyzer angles of the 2 x 2 cell, row by "
                    "row (default 90,45,135,0: the common Sony sensor)")
    ap.add_argument("--demosaic", default="superpixel", choices=("superpixel", "bilinear"),
                    help="--mosaic: superpixel (half resolution, independent pixels; default) or bilinear (full grid, "
                         "correlated neighbours)")
    ap.add_argument("--retarder", help="--frames: FAST,RETARDANCE (deg) of a retarder in front of every analyzer")
    reads(ap.add_argument("--analysis", help="calibrated analysis matrix (.npy, (N, 4) or (H, W, N, 4)) instead of the "
                    "ideal analyzers"))
    ap.add_argument("--gain", type=float, default=1.0, help="DN per electron (default 1)")
    ap.add_argument("--read-noise", type=float, default=0.0, help="read noise in electrons rms (default 0)")
    ap.add_argument("--full-well", type=float, default=math.inf, help="full well in electrons (default inf)")
    ap.add_argument("--black-level", type=float, default=0.0, help="black level in DN (default 0)")
    ap.add_argument("--dn-per-unit", type=float, default=1.0, help="radiometric calibration: DN per scene "
                    "radiance unit at this exposure; the EXR is divided by it (default 1: the EXR in DN)")
    ap.add_argument("--saturated", default="error", choices=("error", "mask"),
                    help="saturated pixels: refuse (default) or leave them out (mask channel 0)")
    writes(ap.add_argument("-o", "--output", required=True, help="output Stokes EXR"))
    writes(ap.add_argument("--png", default=None, help="stem of the intensity/DoLP/AoLP charts (default: beside -o)"))
    quiet_option(ap)
    return ap


def _angles(text, what):
    try:
        vals = [float(x) for x in str(text).split(",") if x.strip()]
    except ValueError:
        raise UsageError(f"{what} must be comma-separated angles in deg, got {text!r}") from None
    if not all(math.isfinite(v) for v in vals):
        raise UsageError(f"{what} must be finite angles in deg, got {text!r}")
    return vals


def read_frame(path, what: str = "frame") -> np.ndarray:
    """A raw frame from ``.npy`` or a grey PNG/TIFF (8 or 16 bit), as an array, sized from its header
    before it is decoded (:func:`hyde_bsdf.io.arrays.read_array`; UsageError naming it)."""
    from hyde_bsdf.io.arrays import read_array

    return read_array(path, what)


#: the charts ``stokes`` writes beside its EXR
CHARTS = ("intensity", "dolp", "aolp")


def cli_main(argv=None) -> int:
    from hyde_bsdf.io.output_gate import output_gate

    parser = build_parser()
    args = parser.parse_args(sys.argv[1:] if argv is None else argv)
    out, stem = _outputs(args)
    charts = [Path(f"{stem}_{name}.png") for name in CHARTS]
    inputs = run_inputs(parser, args)
    # the output gate: no output is an input, one writer at a time; the free space once the size is known
    with output_gate([out, *charts], inputs=inputs, what="-o/--output file"):
        est = _checked(_estimate(args), f"--mosaic {shorten(args.mosaic)}" if args.mosaic else
                       f"the {len(args.frames)} --frames")
        _check_room(est, out, charts)
        paths = _write(est, out, stem, args.dn_per_unit)
    _report(est, paths)
    return 0


def _outputs(args) -> tuple[Path, Path]:
    """(-o, the charts' stem), every output path checked before any frame is read."""
    from hyde_bsdf.io.output_gate import check_output_path

    out = check_output_path(args.output, "-o/--output file")
    if out.suffix.lower() != ".exr":
        raise UsageError(f"-o/--output must end in .exr, got {shorten(args.output)}")
    stem = Path(args.png) if args.png else out.with_suffix("")
    for name in CHARTS:
        check_output_path(Path(f"{stem}_{name}.png"), "--png chart")
    return out, stem


def _check_room(est, out: Path, charts) -> None:
    """The output gate's free-space check of each output folder for the EXR (every Stokes, sigma
    and mask value as float32, :func:`~hyde_bsdf.io.stokes_exr.exr_bytes`) and the charts, before
    anything is written (the Stokes step itself takes seconds)."""
    from hyde_bsdf.app.pictures import chart_bytes
    from hyde_bsdf.io.output_gate import check_free_space
    from hyde_bsdf.io.stokes_exr import exr_bytes

    h, w = est.shape
    values = sum(np.size(a) for a in (*est.stokes.values(), *est.sigma.values())) + h * w
    need = exr_bytes(w, h, -(-values // (h * w))) + len(charts) * chart_bytes(w, h)
    for folder in sorted({str(p.parent) for p in (out, *charts)}):
        check_free_space(folder, need, f"-o/--output {shorten(str(out))} ({w}x{h} px)")


def _check_memory(args) -> None:
    """The Stokes step's peak memory, from the frames' headers (nothing decoded yet), against the
    available memory (:data:`~hyde_bsdf.resources.COSTS`)."""
    from hyde_bsdf.io.arrays import array_header
    from hyde_bsdf.resources import COSTS, check_memory

    files = [args.mosaic] if args.mosaic else list(args.frames)
    values = sum(math.prod(array_header(f, "--mosaic" if args.mosaic else "--frames")[0]) for f in files)
    bilinear = bool(args.mosaic) and args.demosaic == "bilinear"
    per = COSTS.stokes_bilinear_bytes_per_value if bilinear else COSTS.stokes_bytes_per_value
    check_memory(values * per, f"the Stokes images of {len(files)} frame(s), {values} raw values ({per} B each)",
                 "crop the frames" + ("" if not bilinear else ", or use --demosaic superpixel (a quarter of it)"))


def _estimate(args):
    """The Stokes estimate of --mosaic or --frames, in the units of --dn-per-unit."""
    from hyde_bsdf.model.polarimetry import CameraNoise, analysis_matrix, stokes_from_frames, stokes_from_mosaic

    _check_memory(args)
    noise = CameraNoise(args.gain, args.read_noise, args.full_well, args.black_level)
    A = None
    if args.analysis:
        A = read_frame(args.analysis, "--analysis").astype(np.float64)
    if args.mosaic:
        if args.angles or args.retarder:
            raise UsageError("--angles and --retarder go with --frames; a --mosaic has --layout")
        lay = _angles(args.layout, "--layout")
        if len(lay) != 4:
            raise UsageError(f"--layout needs 4 angles (the 2 x 2 cell row by row), got {args.layout!r}")
        est = stokes_from_mosaic(read_frame(args.mosaic, "--mosaic"), (lay[:2], lay[2:]), method=args.demosaic, analysis=A,
                                 noise=noise, saturated=args.saturated, name=args.mosaic)
    else:
        if (args.angles is None) == (A is None):
            raise UsageError("--frames needs --angles (or a calibrated --analysis matrix)")
        angles = _angles(args.angles, "--angles") if args.angles else None
        ret = _angles(args.retarder, "--retarder") if args.retarder else None
        if ret is not None and len(ret) != 2:
            raise UsageError(f"--retarder is FAST,RETARDANCE in deg, got {args.retarder!r}")
        if A is None and ret is not None:
            A = analysis_matrix(angles, retarder=tuple(ret))
        est = stokes_from_frames([read_frame(f, "--frames") for f in args.frames], angles if A is None else None, analysis=A,
                                 noise=noise, saturated=args.saturated, names=args.frames)
    return est.in_units(args.dn_per_unit)


def _checked(est, name: str):
    """The estimate after calibration: pixels no light gives (S0 < 0, a degree of polarization > 1, beyond
    5 sigma; a wrong black level or analysis matrix, a scene that moved between frames) are warned with
    their share (:func:`~hyde_bsdf.inverse.camera_data.impossible_pixels`) and get mask 0 in the EXR."""
    from hyde_bsdf.inverse.camera_data import impossible_pixels

    h, w = est.shape

    def layers(d):          # (4, H, W * C): each colour channel a pixel of its own; missing components 0
        flat = {c: np.asarray(v, np.float64).reshape(h, -1) for c, v in d.items()}
        n = next(iter(flat.values())).shape[1]
        return np.stack([flat.get(c, np.zeros((h, n))) for c in ("S0", "S1", "S2", "S3")])

    bad = impossible_pixels(layers(est.stokes), layers(est.sigma), f"the Stokes estimate of {name}")
    bad = bad.reshape(h, w, -1).any(axis=-1)
    if bad.any():
        est.mask = est.mask & ~bad
    return est


def _write(est, out: Path, stem: Path, dn_per_unit: float) -> dict:
    """The EXR, then its charts (each file replaces its old version once complete)."""
    from hyde_bsdf.app.pictures import save_polarization_pngs
    from hyde_bsdf.model.polarimetry import chart_stokes, write_stokes_estimate

    paths = {"exr": write_stokes_estimate(est, out, metadata={"dn_per_unit": f"{dn_per_unit:g}"})}
    paths.update(save_polarization_pngs(chart_stokes(est), stem, out.stem, charts=CHARTS))
    return paths


def _report(est, paths) -> None:
    h, w = est.shape
    lit = est.mask[..., None] & (est.stokes["S0"].reshape(h, w, -1) > 10 * est.sigma["S0"].reshape(h, w, -1))
    rel = ", ".join(f"{c} {np.median(est.sigma[c].reshape(h, w, -1)[lit] / est.stokes['S0'].reshape(h, w, -1)[lit]):.3g}"
                    for c in est.measured) if lit.any() else "no pixel with S0 > 10 sigma"
    print(f"{'+'.join(est.measured)} at {w}x{h} px ({est.method}; analysis matrix condition {est.condition:.3g}); "
          f"median sigma/S0 where S0 > 10 sigma: {rel}; {int((~est.mask).sum())} pixel(s) masked")
    print("wrote " + ", ".join(str(p) for p in paths.values()))
