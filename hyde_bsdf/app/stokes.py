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

from hyde_bsdf.app.args import Parser, quiet_option
from hyde_bsdf.errors import UsageError, shorten

__all__ = ["build_parser", "cli_main", "read_frame"]


def build_parser():
    ap = Parser(prog="hyde-bsdf stokes", description="Stokes images (S0, S1, S2[, S3]) with per-component "
                 "standard deviations from raw analyzer frames: N >= 3 frames at known analyzer angles, or one "
                 "division-of-focal-plane mosaic.  Least squares through the analysis matrix; the camera's "
                 "noise (gain, read noise) propagated to sigma.")
    src = ap.add_mutually_exclusive_group(required=True)
    src.add_argument("--mosaic", help="one DoFP raw mosaic (.npy, PNG or TIFF; H, W even)")
    src.add_argument("--frames", nargs="+", help="N >= 3 raw frames behind analyzers at --angles")
    ap.add_argument("--angles", help="analyzer angles of --frames in deg, comma-separated (counter-clockwise "
                    "from image right towards image up)")
    ap.add_argument("--layout", default="90,45,135,0", help="--mosaic: analyzer angles of the 2 x 2 cell, row by "
                    "row (default 90,45,135,0: the common Sony sensor)")
    ap.add_argument("--demosaic", default="superpixel", choices=("superpixel", "bilinear"),
                    help="--mosaic: superpixel (half resolution, independent pixels; default) or bilinear (full grid, "
                         "correlated neighbours)")
    ap.add_argument("--retarder", help="--frames: FAST,RETARDANCE (deg) of a retarder in front of every analyzer")
    ap.add_argument("--analysis", help="calibrated analysis matrix (.npy, (N, 4) or (H, W, N, 4)) instead of the "
                    "ideal analyzers")
    ap.add_argument("--gain", type=float, default=1.0, help="DN per electron (default 1)")
    ap.add_argument("--read-noise", type=float, default=0.0, help="read noise in electrons rms (default 0)")
    ap.add_argument("--full-well", type=float, default=math.inf, help="full well in electrons (default inf)")
    ap.add_argument("--black-level", type=float, default=0.0, help="black level in DN (default 0)")
    ap.add_argument("--dn-per-unit", type=float, default=1.0, help="radiometric calibration: DN per scene "
                    "radiance unit at this exposure; the EXR is divided by it (default 1: the EXR in DN)")
    ap.add_argument("--saturated", default="error", choices=("error", "mask"),
                    help="saturated pixels: refuse (default) or leave them out (mask channel 0)")
    ap.add_argument("-o", "--output", required=True, help="output Stokes EXR")
    ap.add_argument("--png", default=None, help="stem of the intensity/DoLP/AoLP charts (default: beside -o)")
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


def read_frame(path) -> np.ndarray:
    """A raw frame from ``.npy`` or a grey PNG/TIFF (8 or 16 bit), as an array (UsageError naming it)."""
    path = Path(path)
    if not path.is_file():
        raise UsageError(f"frame {str(path)!r}: no such file")
    try:
        if path.suffix.lower() == ".npy":
            return np.load(path, allow_pickle=False)
        from PIL import Image

        with Image.open(path) as im:
            return np.asarray(im)
    except (OSError, ValueError) as exc:
        raise UsageError(f"frame {str(path)!r}: cannot read it ({str(exc).splitlines()[0][:120]}); give .npy, "
                         f"PNG or TIFF") from None


#: the charts ``stokes`` writes beside its EXR
CHARTS = ("intensity", "dolp", "aolp")


def cli_main(argv=None) -> int:
    from hyde_bsdf.io.output_gate import output_gate

    args = build_parser().parse_args(sys.argv[1:] if argv is None else argv)
    out, stem = _outputs(args)
    charts = [Path(f"{stem}_{name}.png") for name in CHARTS]
    inputs = [p for p in [args.mosaic, args.analysis, *(args.frames or [])] if p]
    # the output gate: no output is an input, one writer at a time; the free space once the size is known
    with output_gate([out, *charts], inputs=inputs, what="-o/--output file"):
        est = _estimate(args)
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


def _estimate(args):
    """The Stokes estimate of --mosaic or --frames, in the units of --dn-per-unit."""
    from hyde_bsdf.model.polarimetry import CameraNoise, analysis_matrix, stokes_from_frames, stokes_from_mosaic

    noise = CameraNoise(args.gain, args.read_noise, args.full_well, args.black_level)
    A = None
    if args.analysis:
        A = read_frame(args.analysis).astype(np.float64)
    if args.mosaic:
        if args.angles or args.retarder:
            raise UsageError("--angles and --retarder go with --frames; a --mosaic has --layout")
        lay = _angles(args.layout, "--layout")
        if len(lay) != 4:
            raise UsageError(f"--layout needs 4 angles (the 2 x 2 cell row by row), got {args.layout!r}")
        est = stokes_from_mosaic(read_frame(args.mosaic), (lay[:2], lay[2:]), method=args.demosaic, analysis=A,
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
        est = stokes_from_frames([read_frame(f) for f in args.frames], angles if A is None else None, analysis=A,
                                 noise=noise, saturated=args.saturated, names=args.frames)
    return est.in_units(args.dn_per_unit)


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
