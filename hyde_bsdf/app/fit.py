"""``hyde-bsdf fit``: a Mueller-matrix CSV (:func:`csv_main`) or a measured_polarized table
(:func:`pbsdf_main`), told apart by :func:`is_pbsdf`.

Command lines::

    hyde-bsdf fit DATA.csv [--fit n,k,rms_slope] [--rms-slope X] [--n0 N] [--k0 K]
                  [--shadowing vgroove|smith|none] [--diffuse paper|reciprocal|none]
                  [--strict] [-o plot.png] [-q]
    hyde-bsdf fit FILE.pbsdf [--fit n,k,rms_slope] [--rms-slope 0.3] [--n0 N] [--k0 K]
                  [--shadowing vgroove|smith|none] [--diffuse paper|reciprocal|none]
                  [--max-points 3000] [--theta-max 80] [--tolerance 0.05] [--seed 0]
                  [--strict] [-o fit.png] [-q]

(CSV format: :mod:`hyde_bsdf.io.measurements`; the fits: :mod:`hyde_bsdf.fit.mueller_fit`,
:mod:`hyde_bsdf.fit.pbsdf_fit`.)  Options and the ``-o`` path are checked before the file is
read; a user error prints one line on stderr and exits 2; an ill-posed fit with ``--strict`` or
a fit that did not converge exits 1.  Large files report reading and fitting progress on stderr
every few seconds (``-q``: none).
"""
from __future__ import annotations

import math
import warnings
from pathlib import Path

from hyde_bsdf.app.args import Parser, quiet_option, user_input
from hyde_bsdf.app.plots import PLOT_FORMATS, check_plot_path, plot_fit, plot_pbsdf_fit
from hyde_bsdf.errors import UsageError
from hyde_bsdf.fit.mueller_fit import FitDataWarning, IllPosedFitWarning, check_options, fit_measurements
from hyde_bsdf.fit.pbsdf_fit import _check, fit_pbsdf
from hyde_bsdf.fit.pbsdf_samples import pbsdf_samples
from hyde_bsdf.io.measurements import read_measurements
from hyde_bsdf.io.pbsdf_file import read_pbsdf
from hyde_bsdf.model.evaluator import DIFFUSE
from hyde_bsdf.model.shadowing import SHADOWING
from hyde_bsdf.progress import stderr_lines

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


def csv_parser() -> Parser:
    ap = Parser(
        prog="hyde-bsdf fit",
        description="Fit the Hyde-Schmidt-Havrilla pBRDF (n, k, rms_slope) to normalized Mueller-matrix "
                    "measurements in a CSV file (format: python -m pydoc hyde_bsdf.io.measurements). "
                    "The index is the paper's eta = n - jk (the plugin's eta = n, k = k). "
                    "Exit status: 0 fitted, 1 not converged or ill-posed with --strict, 2 bad input.")
    ap.add_argument("data", help="measurement CSV (theta_i_deg, theta_r_deg, phi_deg, M01, M01_sigma, ...)")
    ap.add_argument("--fit", default="n,k", help="comma-separated parameters to fit, from n,k,rms_slope "
                    "(default n,k)")
    ap.add_argument("--rms-slope", type=float, default=0.3,
                    help="rms_slope = sqrt(2) sigma_h/ell: start value if fitted, else held fixed (default 0.3)")
    ap.add_argument("--n0", type=float, default=None, help="start (or fixed) n; default: several starts")
    ap.add_argument("--k0", type=float, default=None, help="start (or fixed) k; default: several starts")
    ap.add_argument("--shadowing", default="vgroove", choices=SHADOWING,
                    help="shadowing-masking: the paper's V-groove, Smith's for Beckmann, or none (default %(default)s)")
    ap.add_argument("--diffuse", default="paper", choices=DIFFUSE,
                    help="diffuse term: the paper's, a reciprocal variant, or none (default %(default)s)")
    ap.add_argument("--strict", action="store_true", help="fail (exit 1) when the fit is ill-posed")
    ap.add_argument("-o", "--output", default=None,
                    help=f"save a plot of data against the model here ({', '.join(PLOT_FORMATS)})")
    quiet_option(ap)
    return ap


def csv_main(argv=None) -> int:
    """``hyde-bsdf fit DATA.csv``: read, fit, print the result and the plugin snippet, plot.

    Options and the output path are checked before the file is read.  Exit status 0 fitted, 1 not
    converged (an ill-posed fit with ``--strict`` raises, 1 too); user errors raise UsageError.
    """
    args = csv_parser().parse_args(argv)
    opts = dict(fit=args.fit, rms_slope=args.rms_slope, n0=args.n0, k0=args.k0,
                shadowing=args.shadowing, diffuse=args.diffuse)
    with user_input():
        check_options(**opts)
    if args.output:
        check_plot_path(args.output)
    meas = read_measurements(args.data, progress=_progress(args))
    with warnings.catch_warnings(), user_input(f"data file {args.data!r}"):
        warnings.simplefilter("ignore", IllPosedFitWarning)   # printed in the summary instead
        warnings.simplefilter("ignore", FitDataWarning)
        result = fit_measurements(meas, **opts, strict=args.strict, progress=_progress(args, auto=True))
    print(f"data: {meas.source} ({len(meas)} rows, elements {', '.join(meas.elements)}"
          + (", sigma / sqrt(n_samples)" if meas.n_samples is not None else "") + ")")
    print(result.summary())
    for text in result.data_warnings:          # also on stderr, where a script's log sees them
        warnings.warn(text, FitDataWarning, stacklevel=1)
    print("\nMitsuba material (hyde plugin):")
    print(result.plugin_xml(indent="    "))
    if args.output:
        plot_fit(result, meas, args.output, title=str(meas.source))
        print(f"\nplot: {args.output}")
    return 0 if result.success else 1


def pbsdf_parser() -> Parser:
    ap = Parser(prog="hyde-bsdf fit", description=(
        "Fit the Hyde-Schmidt-Havrilla pBRDF to a Mitsuba measured_polarized table (FILE.pbsdf, e.g. the KAIST "
        "database): one rms_slope and n, k per band, from M00 and the 15 normalized elements; prints the cell "
        "counts (NaN, non-physical, below the horizon), the fit with standard errors, and the hyde <bsdf>. "
        "Index: the paper's eta = n - jk (the plugin's eta = n, k = k). Exit status: 0 fitted, 1 not converged "
        "or ill-posed with --strict, 2 bad input."))
    ap.add_argument("data", help="the measured_polarized table (.pbsdf)")
    ap.add_argument("--fit", default="n,k,rms_slope", help="parameters to fit (default n,k,rms_slope)")
    ap.add_argument("--rms-slope", type=float, default=0.3, help="start (or fixed) rms_slope (default 0.3)")
    ap.add_argument("--n0", type=float, default=None, help="start (or fixed) n of every band; default: several")
    ap.add_argument("--k0", type=float, default=None, help="start (or fixed) k of every band; default: several")
    ap.add_argument("--shadowing", default="vgroove", choices=SHADOWING,
                    help="shadowing-masking: the paper's V-groove, Smith's for Beckmann, or none (default %(default)s)")
    ap.add_argument("--diffuse", default="paper", choices=DIFFUSE,
                    help="diffuse term: the paper's, a reciprocal variant, or none (default %(default)s)")
    ap.add_argument("--max-points", type=int, default=3000, help="geometries drawn from the usable cells (default 3000)")
    ap.add_argument("--theta-max", type=float, default=80.0,
                    help="largest theta_i, theta_r used, degrees (default 80)")
    ap.add_argument("--tolerance", type=float, default=0.05,
                    help="a cell with |M_jk| or a degree of polarization above (1 + tolerance) M00 is non-physical")
    ap.add_argument("--seed", type=int, default=0, help="seed of the subsample (default 0)")
    ap.add_argument("--strict", action="store_true", help="fail (exit 1) when the fit is ill-posed")
    ap.add_argument("-o", "--output", default=None, help="plot of the fit against the table per Mueller element")
    quiet_option(ap)
    return ap


def pbsdf_main(argv=None) -> int:
    """``hyde-bsdf fit FILE.pbsdf``: read, mask, subsample, fit, print, plot."""
    args = pbsdf_parser().parse_args(argv)
    with user_input():
        fit = _check(args.fit, args.rms_slope, args.n0, args.k0, args.shadowing, args.diffuse)
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
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", IllPosedFitWarning)
        result = fit_pbsdf(data, fit=fit, rms_slope=args.rms_slope, n0=args.n0, k0=args.k0,
                           shadowing=args.shadowing, diffuse=args.diffuse, strict=args.strict,
                           progress=_progress(args))
    print(result.summary())
    print("\nMitsuba material (hyde plugin):")
    print(result.plugin_xml(indent="    "))
    if args.output:
        plot_pbsdf_fit(result, data, args.output, title=str(args.data))
        print(f"\nplot: {args.output}")
    return 0 if result.success else 1
