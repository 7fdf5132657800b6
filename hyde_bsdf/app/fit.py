"""``hyde-bsdf fit``: a Mueller-matrix CSV (:func:`csv_main`) or a measured_polarized table
(:func:`pbsdf_main`), told apart by :func:`is_pbsdf`.

Command lines::

    hyde-bsdf fit DATA.csv [--fit n,k,rms_slope] [--rms-slope X] [--n0 N] [--k0 K]
                  [--model auto|fixed] [--shadowing vgroove|smith|none] [--diffuse paper|reciprocal|none]
                  [--sigma-h-wl H | --sigma-h-um UM --wavelength-nm NM] [--strict] [-o plot.png] [-q]
    hyde-bsdf fit FILE.pbsdf [--fit n,k,rms_slope] [--rms-slope 0.3] [--n0 N] [--k0 K]
                  [--model auto|fixed] [--shadowing vgroove|smith|none] [--diffuse paper|reciprocal|none]
                  [--max-points 3000] [--theta-max 80] [--tolerance 0.05] [--seed 0]
                  [--strict] [-o fit.png] [-q]

Without ``--shadowing`` and ``--diffuse`` the model is chosen (``--model auto``,
:mod:`hyde_bsdf.fit.model_selection`): every shadowing x diffuse model is fitted and the smallest
adequate one kept; the table of models is printed and, with ``-o``, plotted (misfit against model
size) beside the fit as ``NAME_models.EXT``.  Every fit prints its verdict
(:mod:`hyde_bsdf.fit.adequacy`); an inadequate model is a ``WARNING:`` line in the summary and on
stderr.  Told the surface height (``--sigma-h-wl``, or ``--sigma-h-um`` and ``--wavelength-nm``), a CSV fit also
states the accuracy atlas's verdict on the fitted model at the data's incidence angles
(:func:`hyde_bsdf.model.accuracy.verdict`: how far the model may be from exact EM there).

(CSV format: :mod:`hyde_bsdf.io.measurements`; the fits: :mod:`hyde_bsdf.fit.mueller_fit`,
:mod:`hyde_bsdf.fit.pbsdf_fit`.)  Options and the ``-o`` path are checked before the file is
read; a user error prints one line on stderr and exits 2; a fit that did not converge, or with
``--strict`` an inadequate model or an ill-posed fit, exits 1 (after the summary).  Large files report reading and fitting progress on stderr
every few seconds (``-q``: none).
"""
from __future__ import annotations

import contextlib
import math
import warnings
from pathlib import Path

from hyde_bsdf.app.accuracy import add_height_options, fit_verdict, height_wl, pbsdf_verdict_lines
from hyde_bsdf.app.args import Parser, quiet_option, user_input
from hyde_bsdf.app.plots import PLOT_FORMATS, check_plot_path, plot_fit, plot_pbsdf_fit, plot_selection
from hyde_bsdf.errors import RejectedResult, UsageError
from hyde_bsdf.fit.adequacy import InadequateModelWarning
from hyde_bsdf.fit.model_selection import select_model, select_model_pbsdf
from hyde_bsdf.fit.mueller_fit import FitDataWarning, IllPosedFitWarning, check_options, fit_measurements
from hyde_bsdf.io.input_gate import STDIN, check_input
from hyde_bsdf.io.output_gate import output_gate
from hyde_bsdf.fit.pbsdf_fit import _check, fit_pbsdf
from hyde_bsdf.fit.pbsdf_samples import pbsdf_samples
from hyde_bsdf.io.measurements import read_measurements
from hyde_bsdf.io.pbsdf_file import read_pbsdf
from hyde_bsdf.model.terms import DIFFUSE, SHADOWING
from hyde_bsdf.progress import stderr_lines
from hyde_bsdf.resources import COSTS

__all__ = ["is_pbsdf", "cli_main", "csv_main", "pbsdf_main", "csv_parser", "pbsdf_parser"]


def _progress(args, auto: bool = False):
    """The progress callback of a command: stderr lines, or none with ``-q``; ``auto``: the
    library's default (lines only for a large problem) unless ``-q``."""
    if args.quiet:
        return False
    return None if auto else stderr_lines()


def is_pbsdf(path) -> bool:
    """Whether ``path`` names a measured_polarized table: by its suffix, or by the header of a
    regular file (a pipe or a device is never read here: its bytes belong to the reader)."""
    p = Path(path)
    if p.suffix.lower() == ".pbsdf":
        return True
    try:       # sniff regular files only: a FIFO would block, stdin would lose its first bytes
        if check_input(p, "data file") == STDIN:
            return False
    except UsageError:
        return False        # the CSV reader's input gate refuses it with one line
    try:
        if not p.is_file():
            return False
        with open(p, "rb") as f:
            return f.read(12) == b"tensor_file\0"
    except OSError:
        return False


def _data_file(argv):
    """The data file among ``argv``, wherever the options stand (``--fit n,k t.pbsdf`` as well
    as ``t.pbsdf --fit n,k``); None when there is none or the options do not parse."""
    try:
        args, _ = pbsdf_parser().parse_known_args(argv)   # its options are a superset of the CSV's
    except (UsageError, SystemExit):
        return None
    return args.data


def cli_main(argv=None) -> int:
    """``hyde-bsdf fit FILE``: a ``.pbsdf`` table (:func:`pbsdf_main`) or a CSV (:func:`csv_main`)."""
    argv = list(argv or [])
    if any(a in ("-h", "--help") for a in argv):
        print(pbsdf_parser().format_help().replace("usage: hyde-bsdf fit", "usage: hyde-bsdf fit FILE.pbsdf", 1))
        print("----- Mueller-matrix CSV files -----")
        return csv_main(argv)
    data = _data_file(argv)
    return pbsdf_main(argv) if data is not None and is_pbsdf(data) else csv_main(argv)


MODEL_HELP = ("auto (the default unless --shadowing or --diffuse is given): fit every shadowing x diffuse "
              "model (and k = 0 where the data allow a dielectric) and keep the smallest adequate one; "
              f"fixed: one model, --shadowing (default {SHADOWING[0]}) and --diffuse (default {DIFFUSE[0]})")
STRICT_HELP = "fail (exit 1, after the summary) when the model does not describe the data or the fit is ill-posed"


def _add_model_options(ap):
    ap.add_argument("--model", default=None, choices=("auto", "fixed"), help=MODEL_HELP)
    ap.add_argument("--shadowing", default=None, choices=SHADOWING, help=f"one shadowing model (default {SHADOWING[0]})")
    ap.add_argument("--diffuse", default=None, choices=DIFFUSE, help=f"one diffuse term (default {DIFFUSE[0]})")


def _auto(args) -> bool:
    """Whether the command chooses the model: --model auto, or neither --shadowing nor --diffuse."""
    named = args.shadowing is not None or args.diffuse is not None
    if args.model == "auto" and named:
        raise UsageError("--model auto chooses the shadowing and the diffuse term: drop --shadowing/--diffuse, "
                         "or use --model fixed")
    if args.model is None:
        return not named
    return args.model == "auto"


def _models_path(output) -> Path:
    """Where ``-o PATH`` puts the misfit-against-model-size plot: PATH_models.EXT."""
    p = Path(output)
    return p.with_name(p.stem + "_models" + p.suffix)


def _quiet_fit(fn, *args, **kwargs):
    """Run a fit with its warnings kept for the summary (printed there, not twice)."""
    with warnings.catch_warnings():
        for category in (IllPosedFitWarning, FitDataWarning, InadequateModelWarning):
            warnings.simplefilter("ignore", category)
        return fn(*args, **kwargs)


def _warn_verdict(result):
    """An inadequate model's WARNING again on stderr, where a script's log sees it."""
    if not result.verdict.adequate:
        warnings.warn(result.verdict.message, InadequateModelWarning, stacklevel=1)


def _finish(result, strict) -> int:
    """Exit status after the summary: 1 for --strict failures (said on stderr) or no convergence."""
    v = result.verdict
    if strict and (not v.adequate or result.warnings):
        why = v.message if not v.adequate else "ill-posed fit: " + "; ".join(result.warnings)
        raise RejectedResult(f"--strict: {why}")
    return 0 if result.success else 1


def csv_parser() -> Parser:
    ap = Parser(
        prog="hyde-bsdf fit",
        description="Fit the Hyde-Schmidt-Havrilla pBRDF (n, k, rms_slope) to normalized Mueller-matrix "
                    "measurements in a CSV file (format: python -m pydoc hyde_bsdf.io.measurements). "
                    "The index is the paper's eta = n - jk (the plugin's eta = n, k = k). "
                    "Exit status: 0 fitted, 1 not converged, or with --strict an inadequate model or an ill-posed "
                    "fit, 2 bad input.")
    ap.add_argument("data", help="measurement CSV (theta_i_deg, theta_r_deg, phi_deg, M01, M01_sigma, ...)")
    ap.add_argument("--fit", default="n,k", help="comma-separated parameters to fit, from n,k,rms_slope "
                    "(default n,k)")
    ap.add_argument("--rms-slope", type=float, default=0.3,
                    help="rms_slope = sqrt(2) sigma_h/ell: start value if fitted, else held fixed (default 0.3)")
    ap.add_argument("--n0", type=float, default=None, help="start (or fixed) n; default: several starts")
    ap.add_argument("--k0", type=float, default=None, help="start (or fixed) k; default: several starts")
    _add_model_options(ap)
    add_height_options(ap)
    ap.add_argument("--strict", action="store_true", help=STRICT_HELP)
    ap.add_argument("-o", "--output", default=None,
                    help=f"save a plot of data against the model here ({', '.join(PLOT_FORMATS)}); with --model "
                         "auto also NAME_models.EXT, misfit against model size")
    quiet_option(ap)
    return ap


def csv_main(argv=None) -> int:
    """``hyde-bsdf fit DATA.csv``: read, fit, print the result and the plugin snippet, plot.

    Options and the output path are checked before the file is read.  Exit status 0 fitted, 1 not
    converged (an ill-posed fit with ``--strict`` raises, 1 too); user errors raise UsageError.
    """
    args = csv_parser().parse_args(argv)
    with _output_gate(args):       # the output gate's refusal comes before the file is read
        return _csv_run(args)


def _output_gate(args):
    """The output gate on ``-o`` (and, when the model is chosen, its ``_models`` plot) for the whole
    run: not the data file, one writer at a time, room for each plot (:data:`~hyde_bsdf.resources.COSTS`)."""
    if not args.output:
        return contextlib.nullcontext()
    check_plot_path(args.output)
    with user_input():
        plots = [args.output] + ([_models_path(args.output)] if _auto(args) else [])
    return output_gate(plots, inputs=[args.data], need_bytes=COSTS.plot_file_bytes * len(plots), what="-o plot")


def _csv_run(args) -> int:
    opts = dict(fit=args.fit, rms_slope=args.rms_slope, n0=args.n0, k0=args.k0,
                shadowing=args.shadowing or SHADOWING[0], diffuse=args.diffuse or DIFFUSE[0])
    sel = None
    with user_input():
        auto = _auto(args)
        check_options(**opts)
        sigma_h_wl = height_wl(args)
    if args.output:
        check_plot_path(args.output)
    meas = read_measurements(args.data, progress=_progress(args))
    with user_input(f"data file {args.data!r}", library=True):
        if auto:
            sel = _quiet_fit(select_model, meas.theta_i, meas.theta_r, meas.phi, meas.values,
                             sigma=meas.uncertainty(), fit=args.fit, rms_slope=args.rms_slope, n0=args.n0,
                             k0=args.k0, progress=_progress(args, auto=True))
            result = sel.result
        else:
            result = _quiet_fit(fit_measurements, meas, **opts, progress=_progress(args, auto=True))
    print(f"data: {meas.source} ({len(meas)} rows, elements {', '.join(meas.elements)}"
          + (", sigma / sqrt(n_samples)" if meas.n_samples is not None else "") + ")")
    if sel is not None:
        print(sel.summary())
    print(result.summary())
    if sigma_h_wl is not None:
        print(fit_verdict(meas.theta_i, result.params, result.shadowing, result.diffuse, sigma_h_wl))
    _warn_verdict(result)
    for text in result.data_warnings:          # also on stderr, where a script's log sees them
        warnings.warn(text, FitDataWarning, stacklevel=1)
    print("\nMitsuba material (hyde plugin):")
    print(result.plugin_xml(indent="    "))
    if args.output:
        with user_input("cannot write the plot"):
            plot_fit(result, meas, args.output, title=str(meas.source))
            if sel is not None:
                print(f"\nmodels plot: {plot_selection(sel, _models_path(args.output), title=str(meas.source))}")
        print(f"\nplot: {args.output}")
    return _finish(result, args.strict)


def pbsdf_parser() -> Parser:
    ap = Parser(prog="hyde-bsdf fit", description=(
        "Fit the Hyde-Schmidt-Havrilla pBRDF to a Mitsuba measured_polarized table (FILE.pbsdf, e.g. the KAIST "
        "database): one rms_slope and n, k per band, from M00 and the 15 normalized elements; prints the cell "
        "counts (NaN, non-physical, below the horizon), the fit with standard errors, and the hyde <bsdf>. "
        "Index: the paper's eta = n - jk (the plugin's eta = n, k = k). Exit status: 0 fitted, 1 not converged, "
        "or with --strict an inadequate model or an ill-posed fit, 2 bad input."))
    ap.add_argument("data", help="the measured_polarized table (.pbsdf)")
    ap.add_argument("--fit", default="n,k,rms_slope", help="parameters to fit (default n,k,rms_slope)")
    ap.add_argument("--rms-slope", type=float, default=0.3, help="start (or fixed) rms_slope (default 0.3)")
    ap.add_argument("--n0", type=float, default=None, help="start (or fixed) n of every band; default: several")
    ap.add_argument("--k0", type=float, default=None, help="start (or fixed) k of every band; default: several")
    _add_model_options(ap)
    ap.add_argument("--max-points", type=int, default=3000, help="geometries drawn from the usable cells (default 3000)")
    ap.add_argument("--theta-max", type=float, default=80.0,
                    help="largest theta_i, theta_r used, degrees (default 80)")
    ap.add_argument("--tolerance", type=float, default=0.05,
                    help="a cell with |M_jk| or a degree of polarization above (1 + tolerance) M00 is non-physical")
    ap.add_argument("--seed", type=int, default=0, help="seed of the subsample (default 0)")
    add_height_options(ap)
    ap.add_argument("--strict", action="store_true", help=STRICT_HELP)
    ap.add_argument("-o", "--output", default=None, help="plot of the fit against the table per Mueller element; "
                    "with --model auto also NAME_models.EXT, misfit against model size")
    quiet_option(ap)
    return ap


def pbsdf_main(argv=None) -> int:
    """``hyde-bsdf fit FILE.pbsdf``: read, mask, subsample, fit, print, plot."""
    args = pbsdf_parser().parse_args(argv)
    with _output_gate(args):
        return _pbsdf_run(args)


def _pbsdf_run(args) -> int:
    with user_input():
        auto = _auto(args)
        shadowing, diffuse = args.shadowing or SHADOWING[0], args.diffuse or DIFFUSE[0]
        fit = _check(args.fit, args.rms_slope, args.n0, args.k0, shadowing, diffuse)
        height_wl(args, wavelength_nm=1000.0)             # the height options checked before the table is read
    if not 0 <= args.seed < 2**32:
        raise UsageError(f"--seed must be an integer in [0, 2^32), got {args.seed}")
    if not 0 < args.theta_max <= 90:
        raise UsageError(f"--theta-max must be in (0, 90] degrees, got {args.theta_max:g}")
    if not 0 <= args.tolerance <= 1:
        raise UsageError(f"--tolerance must be in [0, 1], got {args.tolerance:g}")
    if args.max_points < 1:
        raise UsageError(f"--max-points must be >= 1, got {args.max_points}")
    if args.output:
        check_plot_path(args.output)
    table = read_pbsdf(args.data)
    data = pbsdf_samples(table, max_points=args.max_points, theta_max=math.radians(args.theta_max),
                         tolerance=args.tolerance, seed=args.seed, progress=_progress(args))
    print(f"data: {args.data} ({table.resolution} phi_d x theta_d x theta_h, bands "
          f"{', '.join(f'{w:g}' for w in table.wavelengths)} nm)")
    print(f"  {data.counts.summary()}")
    print(f"  fitting {len(data)} of {data.usable_geometries} geometries usable in every band "
          f"(theta <= {args.theta_max:g} deg, seed {args.seed})")
    opts = dict(fit=fit, rms_slope=args.rms_slope, n0=args.n0, k0=args.k0, progress=_progress(args))
    sel = _quiet_fit(select_model_pbsdf, data, **opts) if auto else None
    result = sel.result if auto else _quiet_fit(fit_pbsdf, data, shadowing=shadowing, diffuse=diffuse, **opts)
    if sel is not None:
        print(sel.summary())
    print(result.summary())
    for line in pbsdf_verdict_lines(data.theta_i, result, args):
        print(line)
    _warn_verdict(result)
    print("\nMitsuba material (hyde plugin):")
    print(result.plugin_xml(indent="    "))
    if args.output:
        plot_pbsdf_fit(result, data, args.output, title=str(args.data))
        print(f"\nplot: {args.output}")
        if sel is not None:
            print(f"models plot: {plot_selection(sel, _models_path(args.output), title=str(args.data))}")
    return _finish(result, args.strict)
