"""``hyde-bsdf fit``: a Mueller-matrix CSV (:func:`csv_main`) or a measured_polarized table
(:func:`pbsdf_main`), told apart by :func:`is_pbsdf`.

Command lines::

    hyde-bsdf fit DATA.csv [--fit rms_slope,n,k,diffuse_reflectance] [--rms-slope X] [--n0 N] [--k0 K]
                  [--diffuse-reflectance A] [--model auto|fixed] [--shadowing vgroove|smith|none]
                  [--diffuse paper|reciprocal|none|lambertian] [--albedo shared|per-wavelength]
                  [--sigma-h-wl H | --sigma-h-um UM [--wavelength-nm NM]] [--json FILE] [--strict] [-o plot.png] [-q]
    hyde-bsdf fit FILE.pbsdf [--fit n,k,rms_slope] [--rms-slope 0.3] [--n0 N] [--k0 K]
                  [--model auto|fixed] [--shadowing vgroove|smith|none] [--diffuse paper|reciprocal|none]
                  [--max-points 3000] [--theta-max 80] [--tolerance 0.05] [--seed 0]
                  [--sigma-h-um UM | --sigma-h-wl H] [--json FILE] [--strict] [-o fit.png] [-q]

A CSV (M00 in 1/sr optional, several wavelengths in one file) is fitted by
:func:`hyde_bsdf.fit.lab.fit_lab`: everything the data determine unless ``--fit`` names fewer,
one joint fit over the wavelengths; ``--json FILE`` writes the machine-readable result
(``-``: to stdout, the summary then on stderr) -- a table's too, in the same schema (n and k per
band at the band's wavelength).  Without ``--shadowing`` and ``--diffuse`` the model is chosen (``--model auto``,
:mod:`hyde_bsdf.fit.model_selection`): every shadowing x diffuse model is fitted and the smallest
adequate one kept; the table of models is printed and, with ``-o``, plotted (misfit against model
size) beside the fit as ``NAME_models.EXT``.  Every fit prints its verdict
(:mod:`hyde_bsdf.fit.adequacy`); an inadequate model is a ``WARNING:`` line in the summary and on
stderr.  Told the surface height (``--sigma-h-wl``, or ``--sigma-h-um`` with the data's wavelength column
or ``--wavelength-nm``), a fit also states the accuracy atlas's verdict on the fitted model at the data's
incidence angles, per wavelength (:func:`hyde_bsdf.model.accuracy.verdict`).

(CSV format: :mod:`hyde_bsdf.io.measurements`; the fits: :mod:`hyde_bsdf.fit.mueller_fit`,
:mod:`hyde_bsdf.fit.pbsdf_fit`.)  Options and the ``-o`` path are checked before the file is
read; a user error prints one line on stderr and exits 2; a fit that did not converge, or with
``--strict`` an inadequate model or an ill-posed fit, exits 1 (after the summary).  Large files report reading and fitting progress on stderr
every few seconds (``-q``: none).
"""
from __future__ import annotations

import contextlib
import json
import math
import sys
import warnings
from pathlib import Path

from hyde_bsdf.app.accuracy import (add_height_options, check_height_options, height_wl, lab_verdict_lines,
                                    pbsdf_verdict_lines)
from hyde_bsdf.app.args import Parser, quiet_option, reads, run_inputs, user_input, writes
from hyde_bsdf.app.flags import for_command_line
from hyde_bsdf.app.plots import (PLOT_FORMATS, check_plot_path, plot_lab_fit, plot_lab_selection, plot_pbsdf_fit,
                                 plot_selection)
from hyde_bsdf.errors import RejectedResult, UsageError
from hyde_bsdf.fit.adequacy import InadequateModelWarning
from hyde_bsdf.fit.model_selection import select_model, select_model_pbsdf
from hyde_bsdf.fit.lab import DIFFUSE_CHOICES, check_lab_options, fit_lab
from hyde_bsdf.fit.spectral import extrapolation_warning
from hyde_bsdf.fit.mueller_fit import FitDataWarning, IllPosedFitWarning
from hyde_bsdf.io.atomic import atomic_open
from hyde_bsdf.io.input_gate import STDIN, check_input
from hyde_bsdf.io.output_gate import output_gate
from hyde_bsdf.fit.pbsdf_fit import _check, fit_pbsdf
from hyde_bsdf.fit.pbsdf_samples import pbsdf_samples
from hyde_bsdf.io.measurements import read_measurements
from hyde_bsdf.io.pbsdf_file import read_pbsdf
from hyde_bsdf.model.parameters import DIFFUSE_REFLECTANCE
from hyde_bsdf.model.terms import DIFFUSE, DIFFUSE_TERMS, SHADOWING
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


#: the diffuse terms a table fit takes: those without parameters of their own (the CSV fit takes every one)
TABLE_DIFFUSE = tuple(t.name for t in DIFFUSE_TERMS if not t.parameters)


def _add_model_options(ap):
    ap.add_argument("--model", default=None, choices=("auto", "fixed"), help=MODEL_HELP)
    ap.add_argument("--shadowing", default=None, choices=SHADOWING, help=f"one shadowing model (default {SHADOWING[0]})")
    ap.add_argument("--diffuse", default=None, choices=TABLE_DIFFUSE, help=f"one diffuse term (default {DIFFUSE[0]})")


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
    ill = getattr(result, "ill_posed_notes", result.warnings)
    if strict and (not v.adequate or ill):
        why = v.message if not v.adequate else "ill-posed fit: " + "; ".join(ill)
        raise RejectedResult(f"--strict: {why}")
    return 0 if result.success else 1


def csv_parser() -> Parser:
    ap = Parser(
        prog="hyde-bsdf fit",
        description="Fit the Hyde-Schmidt-Havrilla pBRDF to Mueller-matrix measurements in a CSV file: the "
                    "normalized elements M_jk/M_00, optionally the BRDF M00 (1/sr) and a wavelength_nm column "
                    "(format: python -m pydoc hyde_bsdf.io.measurements). By default everything the data "
                    "determine is fitted -- rms_slope, n and k per wavelength, the Lambertian albedo -- and the "
                    "model chosen. The index is the paper's eta = n - jk (the plugin's eta = n, k = k). "
                    "Exit status: 0 fitted, 1 not converged, or with --strict an inadequate model or an ill-posed "
                    "fit, 2 bad input.")
    reads(ap.add_argument("data", help="measurement CSV (theta_i_deg, theta_r_deg, phi_deg, M00, M00_sigma, M01, ...)"))
    ap.add_argument("--fit", default=None, help="comma-separated parameters to fit, from rms_slope,n,k,"
                    "diffuse_reflectance (default: all the data determine); the others are held at their values")
    ap.add_argument("--rms-slope", type=float, default=None,
                    help="rms_slope = sqrt(2) sigma_h/ell: start value if fitted (default: a grid), else held fixed")
    ap.add_argument("--n0", type=float, default=None, help="start (or fixed) n at every wavelength; default: a grid")
    ap.add_argument("--k0", type=float, default=None, help="start (or fixed) k at every wavelength; default: a grid")
    ap.add_argument("--diffuse-reflectance", type=float, default=None,
                    help=f"start (or fixed) albedo of the Lambertian diffuse term, in {DIFFUSE_REFLECTANCE.text()}")
    ap.add_argument("--model", default=None, choices=("auto", "fixed"), help=MODEL_HELP)
    ap.add_argument("--shadowing", default=None, choices=SHADOWING, help="one shadowing model (default vgroove)")
    ap.add_argument("--diffuse", default=None, choices=DIFFUSE_CHOICES,
                    help="one diffuse term (default paper): the paper's Eq. 17, its reciprocal variant, none, or a "
                         "Lambertian term with a free albedo (diffuse_reflectance)")
    ap.add_argument("--albedo", default=None, choices=("shared", "per-wavelength"),
                    help="the Lambertian albedo: one for every wavelength, or one per wavelength (default: as the "
                         "data decide with --model auto, else shared)")
    writes(ap.add_argument("--json", default=None, metavar="FILE",
                           help="write the result as JSON (values, standard errors, covariance, verdict, the table "
                                "of models); '-' for stdout (the summary then goes to stderr)"))
    add_height_options(ap)
    ap.add_argument("--strict", action="store_true", help=STRICT_HELP)
    writes(ap.add_argument("-o", "--output", default=None,
                           help=f"save a plot of data against the model here ({', '.join(PLOT_FORMATS)}); with "
                                "--model auto also NAME_models.EXT, misfit against model size"))
    quiet_option(ap)
    return ap


def csv_main(argv=None) -> int:
    """``hyde-bsdf fit DATA.csv``: read, fit, print the result and the plugin snippet, plot, JSON.

    Options and the output paths are checked before the file is read.  Exit status 0 fitted, 1 not
    converged (an ill-posed fit with ``--strict`` raises, 1 too); user errors raise UsageError.
    """
    parser = csv_parser()
    args = parser.parse_args(argv)
    with _output_gate(args, parser):       # the output gate's refusal comes before the file is read
        return _csv_run(args)


def _output_gate(args, parser):
    """The output gate on ``-o`` (and, when the model is chosen, its ``_models`` plot) and on
    ``--json FILE`` for the whole run: not the data file, one writer at a time, room for each
    (:data:`~hyde_bsdf.resources.COSTS`)."""
    plots, json_file = [], getattr(args, "json", None)
    if args.output:
        check_plot_path(args.output)
        with user_input():
            plots = [args.output] + ([_models_path(args.output)] if _auto(args) else [])
    outputs = plots + ([json_file] if json_file and json_file != "-" else [])
    if not outputs:
        return contextlib.nullcontext()
    return output_gate(outputs, inputs=run_inputs(parser, args), need_bytes=COSTS.plot_file_bytes * max(len(outputs), 1),
                       what="-o plot" if plots else "--json file")


def _csv_options(args) -> dict:
    """fit_lab's keywords from the command line, checked (before the data file is read)."""
    auto = _auto(args)
    opts = dict(fit=args.fit, rms_slope=args.rms_slope, n0=args.n0, k0=args.k0,
                diffuse_reflectance=args.diffuse_reflectance,
                albedo=None if args.albedo is None else args.albedo.replace("-", "_"),
                shadowing=None if auto else (args.shadowing or SHADOWING[0]),
                diffuse=None if auto else (args.diffuse or DIFFUSE[0]))
    check_lab_options(**opts)
    check_height_options(args)
    return opts


def _csv_run(args) -> int:
    with user_input():
        opts = _csv_options(args)
    meas = read_measurements(args.data, progress=_progress(args))
    if args.sigma_h_um is not None and meas.wavelength_nm is None:
        height_wl(args)                            # --sigma-h-um needs a wavelength: said before the fit
    with user_input(f"data file {args.data!r}", library=True):
        result = _quiet_fit(fit_lab, meas, **opts, progress=_progress(args, auto=True))
    out = sys.stderr if args.json == "-" else sys.stdout
    print(f"data: {meas.source} ({len(meas)} rows, {', '.join(result.fit.data.columns)}"
          + (", sigma / sqrt(n_samples)" if meas.n_samples is not None else "") + ")", file=out)
    print(for_command_line(result.summary()), file=out)
    for line in lab_verdict_lines(meas, result, args):
        print(line, file=out)
    _warn_verdict(result)
    for text in result.warnings:               # also on stderr, where a script's log sees them
        if text != result.verdict.message and not text.startswith("NO candidate"):
            warnings.warn(text, FitDataWarning, stacklevel=1)
    print("\nMitsuba material (hyde plugin):", file=out)
    print(result.plugin_xml(indent="    "), file=out)
    caveat = extrapolation_warning(result.wavelengths)
    if caveat and result.wavelengths != [None]:       # without a wavelength column: the XML comment says it
        warnings.warn(caveat, UserWarning, stacklevel=1)
    if args.json:
        _write_json(result.to_dict(), args.json)
    if args.output:
        with user_input("cannot write the plot"):
            plot_lab_fit(result, args.output, title=str(meas.source))
            if result.selection is not None:
                models = plot_lab_selection(result, _models_path(args.output), title=str(meas.source))
                print(f"\nmodels plot: {models}", file=out)
        print(f"\nplot: {args.output}", file=out)
    return _finish(result, args.strict)


def _write_json(data: dict, path):
    """The result as JSON: to stdout for '-', else atomically to ``path``."""
    text = json.dumps(data, indent=1, allow_nan=False)
    if path == "-":
        print(text)
        return
    with user_input("cannot write the --json file"):
        with atomic_open(path, "w", encoding="utf-8") as fh:
            fh.write(text + "\n")


def pbsdf_parser() -> Parser:
    ap = Parser(prog="hyde-bsdf fit", description=(
        "Fit the Hyde-Schmidt-Havrilla pBRDF to a Mitsuba measured_polarized table (FILE.pbsdf, e.g. the KAIST "
        "database): one rms_slope and n, k per band, from M00 and the 15 normalized elements; prints the cell "
        "counts (NaN, non-physical, below the horizon), the fit with standard errors, and the hyde <bsdf>. "
        "Index: the paper's eta = n - jk (the plugin's eta = n, k = k). Exit status: 0 fitted, 1 not converged, "
        "or with --strict an inadequate model or an ill-posed fit, 2 bad input."))
    reads(ap.add_argument("data", help="the measured_polarized table (.pbsdf)"))
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
    writes(ap.add_argument("--json", default=None, metavar="FILE",
                           help="write the result as JSON (values per band, standard errors, covariance, verdict, "
                                "the table of models); '-' for stdout (the summary then goes to stderr)"))
    add_height_options(ap)
    ap.add_argument("--strict", action="store_true", help=STRICT_HELP)
    writes(ap.add_argument("-o", "--output", default=None, help="plot of the fit against the table per Mueller "
                           "element; with --model auto also NAME_models.EXT, misfit against model size"))
    quiet_option(ap)
    return ap


def pbsdf_main(argv=None) -> int:
    """``hyde-bsdf fit FILE.pbsdf``: read, mask, subsample, fit, print, plot."""
    parser = pbsdf_parser()
    args = parser.parse_args(argv)
    with _output_gate(args, parser):
        return _pbsdf_run(args)


def _pbsdf_run(args) -> int:
    with user_input():
        auto = _auto(args)
        shadowing, diffuse = args.shadowing or SHADOWING[0], args.diffuse or DIFFUSE[0]
        fit = _check(args.fit, args.rms_slope, args.n0, args.k0, shadowing, diffuse)
        check_height_options(args)                  # a table carries its wavelengths: --sigma-h-um needs no other
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
    out = sys.stderr if args.json == "-" else sys.stdout
    print(f"data: {args.data} ({table.resolution} phi_d x theta_d x theta_h, bands "
          f"{', '.join(f'{w:g}' for w in table.wavelengths)} nm)", file=out)
    print(f"  {data.counts.summary()}", file=out)
    print(f"  fitting {len(data)} of {data.usable_geometries} geometries usable in every band "
          f"(theta <= {args.theta_max:g} deg, seed {args.seed})", file=out)
    opts = dict(fit=fit, rms_slope=args.rms_slope, n0=args.n0, k0=args.k0, progress=_progress(args))
    sel = _quiet_fit(select_model_pbsdf, data, **opts) if auto else None
    result = sel.result if auto else _quiet_fit(fit_pbsdf, data, shadowing=shadowing, diffuse=diffuse, **opts)
    if sel is not None:
        print(for_command_line(sel.summary()), file=out)
    print(for_command_line(result.summary()), file=out)
    for line in pbsdf_verdict_lines(data.theta_i, result, args):
        print(line, file=out)
    _warn_verdict(result)
    print("\nMitsuba material (hyde plugin):", file=out)
    print(result.plugin_xml(indent="    "), file=out)
    caveat = extrapolation_warning([float(w) for w in result.wavelengths])
    if caveat:
        warnings.warn(caveat, UserWarning, stacklevel=1)
    if args.json:
        _write_json(sel.to_dict() if sel is not None else result.to_dict(), args.json)
    if args.output:
        plot_pbsdf_fit(result, data, args.output, title=str(args.data))
        print(f"\nplot: {args.output}", file=out)
        if sel is not None:
            print(f"models plot: {plot_selection(sel, _models_path(args.output), title=str(args.data))}", file=out)
    return _finish(result, args.strict)
