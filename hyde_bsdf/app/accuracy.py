"""``hyde-bsdf accuracy``: how wrong the model may be at your geometry, and the cheapest variant that is not.

Command line::

    hyde-bsdf accuracy --theta-i DEG [--theta-r DEG] --rms-slope S [--n N --k K] [--sigma-h-wl H]
                       [--shadowing vgroove|smith|none] [--diffuse paper|reciprocal|none]
                       [--tol-db 1.0] [--tol 0.1] [--json] [--atlas FILE] [-q]

reads the accuracy atlas (:func:`hyde_bsdf.model.accuracy.accuracy`: every model variant against the
exact MoM on 1-D rough surfaces) and prints, per Mueller element, the expected error of the chosen
variant and whether it is within the tolerance, the cheapest adequate variant, or "unknown" with the
reason.  Without ``--n`` the surface is a perfect conductor; without ``--sigma-h-wl`` the answer
covers every height in the atlas (0.1-4 wavelengths).  ``--json`` prints the answer as JSON.
"""
from __future__ import annotations

import argparse
import json
import math

import numpy as np

from hyde_bsdf.app.args import Parser, quiet_option, reads, user_input
from hyde_bsdf.model.accuracy import TOLERANCE, TOLERANCE_DB, accuracy, load_atlas
from hyde_bsdf.model.terms import DIFFUSE, SHADOWING

__all__ = ["build_parser", "cli_main", "format_answer"]


def build_parser() -> Parser:
    ap = Parser(prog="hyde-bsdf accuracy",
                description="The accuracy atlas's verdict on the model (every shadowing x diffuse variant against "
                            "the exact MoM, 1-D rough surfaces): per Mueller element the expected error and whether "
                            "it is within the tolerance, and the cheapest adequate variant.")
    ap.add_argument("--theta-i", type=float, required=True, metavar="DEG", help="incidence angle (degrees, 0-90)")
    ap.add_argument("--theta-r", type=float, default=None, metavar="DEG",
                    help="signed observation angle in the plane of incidence (degrees, + = specular side); "
                         "default: the whole lobe")
    ap.add_argument("--rms-slope", type=float, required=True, help="the paper's rms_slope = sqrt(2) sigma_h / ell")
    ap.add_argument("--n", type=float, default=None, help="real part of the index n - jk (omit for a perfect conductor)")
    ap.add_argument("--k", type=float, default=None, help="imaginary part k >= 0 (with --n)")
    ap.add_argument("--sigma-h-wl", type=float, default=None, metavar="H",
                    help="rms surface height in wavelengths (default: the range over the atlas's heights)")
    ap.add_argument("--shadowing", default="vgroove", choices=SHADOWING, help="the variant asked about (default %(default)s)")
    ap.add_argument("--diffuse", default="paper", choices=DIFFUSE, help="the variant asked about (default %(default)s)")
    ap.add_argument("--tol-db", type=float, default=TOLERANCE_DB, help="tolerance of M00 in dB (default %(default)g)")
    ap.add_argument("--tol", type=float, default=TOLERANCE,
                    help="tolerance of the normalised elements Mij/M00 (default %(default)g)")
    ap.add_argument("--json", action="store_true", help="print the answer as JSON")
    reads(ap.add_argument("--atlas", default=None, metavar="FILE", help="another atlas table (default: the shipped one)"))
    quiet_option(ap)
    return ap


def _angle(value):
    """Degrees (the command line's unit) to radians (the library's); a non-finite value passes to its check."""
    return None if value is None else math.radians(value) if math.isfinite(value) else value


def cli_main(argv=None) -> int:
    """``hyde-bsdf accuracy``: the verdict as text or JSON on stdout."""
    args = build_parser().parse_args(argv)
    with user_input("", library=True):
        atlas = load_atlas(args.atlas)
        answer = accuracy(_angle(args.theta_i), args.rms_slope, args.n, args.k,
                          theta_r=_angle(args.theta_r), sigma_h_wl=args.sigma_h_wl,
                          shadowing=args.shadowing, diffuse=args.diffuse, tol_db=args.tol_db, tol=args.tol,
                          atlas=atlas)
    print(json.dumps(answer, indent=1) if args.json else format_answer(answer))
    return 0


def _num(x, digits=3):
    return "-" if x is None else f"{x:.{digits}g}"


def format_answer(a) -> str:
    """The answer of :func:`hyde_bsdf.model.accuracy.accuracy` as a few readable lines."""
    q = a["query"]
    index = "perfect conductor" if q["n"] is None else f"n = {q['n']:g}, k = {q['k']:g}"
    mats = " + ".join(f"{w:g} {m}" for m, w in a["material"].get("from", [])) or "none"
    height = "every atlas height" if q["sigma_h_wl"] is None else f"sigma_h = {q['sigma_h_wl']:g} lambda"
    where = "the lobe" if q["theta_r_deg"] is None else f"theta_r = {q['theta_r_deg']:g} deg"
    v = a["variant"]
    lines = [f"theta_i = {q['theta_i_deg']:g} deg, {where}; rms_slope {q['rms_slope']:g}, {height}; {index} "
             f"(atlas material: {mats}; nearest {a['material']['nearest']})",
             f"model {v['shadowing']}/{v['diffuse']} against exact EM (accuracy atlas, 1-D surfaces):"]
    if a["status"] == "unknown" and a.get("region") is None:
        lines.append(f"  unknown: {a['reason']}")
    else:
        lines.append(f"  {'element':10s} {'error':>8s} {'+-se':>7s} {'range':>15s} {'tolerance':>9s}  verdict")
        for name, label in (("M00_dB", "M00 (dB)"), ("M01", "M01/M00"), ("M11", "M11/M00"), ("M22", "M22/M00"),
                            ("M23", "M23/M00")):
            e = a["elements"][name]
            rng = "" if "error_range" not in e else f"{_num(e['error_range'][0])}-{_num(e['error_range'][1])}"
            verdict = e["status"] + (f" ({e['reason']})" if e.get("reason") else "")
            lines.append(f"  {label:10s} {_num(e['error']):>8s} {_num(e['se'], 2):>7s} {rng:>15s} "
                         f"{_num(e.get('tolerance')):>9s}  {verdict}")
        lines.append("  (M10 = M01, M33 = M22, M32 = -M23 and the other 8 elements vanish on a 1-D surface in the "
                     "plane of incidence)")
        c = a["coherent"]
        if c["share"] is not None:
            lines.append(f"coherent (mirror) share of the reflected power, which the model lacks: {_num(c['share'])} "
                         f"({'within' if c['valid'] else 'beyond'} {_num(c['limit'])}, the tolerance's share of M00)")
    r = a["recommended"]
    if r["method"] == "model":
        lines.append(f"recommended: {r['shadowing']}/{r['diffuse']} (the cheapest adequate variant, "
                     f"{r['seconds_per_evaluation']:.2g} s per evaluation)")
    else:
        cost = a.get("mom")
        extra = "" if not cost else (f"; the atlas's MoM took {cost['cpu_seconds']:g} CPU s for its nearest surface "
                                     f"({cost['partitions']} partitions of {cost['partition_wl']:g} lambda, "
                                     "10 incidence angles, s and p)")
        lines.append(f"recommended: the MoM ({r['reason']}){extra}")
    if a.get("advice"):
        lines.append("advice: " + a["advice"])
    return "\n".join(lines)


def add_height_options(ap) -> None:
    """The surface height options of a fit (``--sigma-h-wl``, or ``--sigma-h-um`` with ``--wavelength-nm``): told
    them, the fit states the accuracy atlas's verdict for the fitted model at the data's incidence angles."""
    ap.add_argument("--sigma-h-wl", type=float, default=None, metavar="H",
                    help="rms surface height in wavelengths: the summary then states the accuracy atlas's verdict "
                         "on the fitted model (hyde-bsdf accuracy)")
    ap.add_argument("--sigma-h-um", type=float, default=None, metavar="UM",
                    help="rms surface height in micrometres (with --wavelength-nm): as --sigma-h-wl")
    ap.add_argument("--wavelength-nm", type=float, default=None, metavar="NM",
                    help="the measurement's wavelength in nm (with --sigma-h-um)")


def check_height_options(args) -> None:
    """The height options' own mistakes (both given, a value not positive): UsageError naming the option, before
    the data are read."""
    from hyde_bsdf.errors import UsageError

    if args.sigma_h_wl is not None and args.sigma_h_um is not None:
        raise UsageError("give --sigma-h-wl or --sigma-h-um (with --wavelength-nm), not both")
    for name, v in (("--sigma-h-wl", args.sigma_h_wl), ("--sigma-h-um", args.sigma_h_um),
                    ("--wavelength-nm", args.wavelength_nm)):
        if v is not None and not (math.isfinite(v) and v > 0):
            raise UsageError(f"{name} must be a positive number, got {v:g}")


def height_wl(args, wavelength_nm=None):
    """sigma_h / lambda from the height options at one wavelength (``wavelength_nm``: the data's own, else
    ``--wavelength-nm``); None without a height; UsageError where --sigma-h-um has no wavelength."""
    from hyde_bsdf.errors import UsageError

    check_height_options(args)
    if args.sigma_h_um is None:
        return args.sigma_h_wl
    wl = wavelength_nm if wavelength_nm is not None else args.wavelength_nm
    if wl is None:
        raise UsageError("--sigma-h-um needs the wavelength: a wavelength_nm column in the data or --wavelength-nm "
                         "(the height in wavelengths is what the accuracy atlas reads)")
    return 1000.0 * args.sigma_h_um / wl


def fit_verdict(theta_i, params, shadowing, diffuse, sigma_h_wl) -> str:
    """The atlas's verdict line for a fitted model (``params``: n, k, rms_slope) at the data's incidence angles
    (radians); the pec case is n = None."""
    from hyde_bsdf.model.accuracy import verdict

    v = verdict(theta_i, params["rms_slope"], params.get("n"), params.get("k"), sigma_h_wl=sigma_h_wl,
                shadowing=shadowing, diffuse=diffuse)
    return f"{v['summary']} (sigma_h = {sigma_h_wl:.3g} lambda; details: hyde-bsdf accuracy)"


def pbsdf_verdict_lines(theta_i, result, args) -> list:
    """The atlas's verdict per band of a table fit (``result``: rms_slope, n and k per band, ``wavelengths`` in
    nm), at the atlas's incidence angles within the data's range: ``--sigma-h-um`` gives each band its own
    sigma_h / lambda; ``--sigma-h-wl`` the same for every band.  [] when no height was given."""
    if args.sigma_h_wl is None and args.sigma_h_um is None:
        return []
    lo, hi = float(np.min(theta_i)), float(np.max(theta_i))
    grid = np.radians([t for t in range(0, 90, 10) if math.radians(t) >= lo - 1e-9 and math.radians(t) <= hi + 1e-9])
    lines = []
    for w, n, k in zip(result.wavelengths, result.n, result.k):
        line = fit_verdict(grid if grid.size else [lo], {"rms_slope": result.rms_slope, "n": n, "k": k},
                           result.shadowing, result.diffuse, height_wl(args, w))
        lines.append(f"{w:g} nm: {line}")
    return lines


def lab_verdict_lines(meas, result, args) -> list:
    """The atlas's verdict for a CSV fit (:func:`hyde_bsdf.fit.lab.fit_lab`), one line per wavelength of the data
    (each its own sigma_h / lambda with ``--sigma-h-um``), at the data's incidence angles there.  [] without a
    height."""
    if args.sigma_h_wl is None and args.sigma_h_um is None:
        return []
    lines = []
    for w in result.wavelengths:
        rows = np.ones(len(meas), bool) if w is None or meas.wavelength_nm is None else \
            np.abs(meas.wavelength_nm - w) < 1e-9
        line = fit_verdict(meas.theta_i[rows], result.params(w), result.model.shadowing, result.model.diffuse,
                           height_wl(args, w))
        lines.append(line if w is None else f"{w:g} nm: {line}")
    return lines
