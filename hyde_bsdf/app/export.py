"""``hyde-bsdf export``: the hyde model as a measured_polarized table (:func:`hyde_bsdf.fit.export_pbsdf`).

Command line::

    hyde-bsdf export OUT.pbsdf --rms-slope 0.3 (--material Au | --n N[,N,...] --k K[,K,...])
                     [--shadowing vgroove|smith|none] [--diffuse reciprocal|paper|none|lambertian]
                     [--diffuse-reflectance A[,A,...]] [--band-index projected|sampled]
    hyde-bsdf export OUT.pbsdf --fit FIT.json [--extrapolate]
                     [--resolution 37x55x55] [--error-samples 20000]
                     [--wavelengths auto|W1,W2,W3,W4,W5] [-q]

prints the chosen bands and their colour error, the measured interpolation error and the ``<bsdf>``
element to use.  ``--fit FIT.json`` takes the material of a fit (``hyde-bsdf fit DATA.csv --json
FIT.json``): its roughness, terms and albedo, and its index per wavelength interpolated at the bands
(``--wavelengths``; auto: 450-650 nm) -- refused where a band lies outside the wavelengths the fit
was measured at (every band, for a fit at one wavelength) unless ``--extrapolate`` holds the nearest
measured values there, with a warning.
"""
from __future__ import annotations

import json
import warnings

from hyde_bsdf.app.args import Parser, quiet_option, reads, run_inputs, user_input, writes
from hyde_bsdf.errors import UsageError, shorten
from hyde_bsdf.fit.lab import material_at
from hyde_bsdf.fit.pbsdf_bands import BAND_INDEX, check_wavelengths, choose_bands, index_spectrum
from hyde_bsdf.fit.pbsdf_export import DEFAULT_RESOLUTION, export_pbsdf
from hyde_bsdf.io.input_gate import read_input
from hyde_bsdf.io.output_gate import check_not_input
from hyde_bsdf.io.pbsdf_file import KAIST_WAVELENGTHS
from hyde_bsdf.model.terms import DIFFUSE, RENDER_DEFAULT, SHADOWING
from hyde_bsdf.progress import stderr_lines

__all__ = ["build_parser", "cli_main"]


def _floats(text, name):
    try:
        vals = [float(v) for v in str(text).split(",")]
    except ValueError:
        raise UsageError(f"--{name} must be a number or 5 comma-separated numbers (one per band), got {shorten(text)}") from None
    return vals[0] if len(vals) == 1 else vals


def _material(args) -> dict:
    """export_pbsdf's material and band keywords: from the options, or from ``--fit FIT.json`` (the
    index interpolated between the fit's wavelengths at the bands -- ``--wavelengths``, else 450-650 nm;
    outside them refused, or held with --extrapolate)."""
    albedo = None if args.diffuse_reflectance is None else _floats(args.diffuse_reflectance, "diffuse-reflectance")
    bands = None if args.wavelengths == "auto" else check_wavelengths(_floats(args.wavelengths, "wavelengths"))
    if args.fit is None:
        if args.extrapolate:
            raise UsageError("--extrapolate applies to --fit")
        if args.rms_slope is None:
            raise UsageError("--rms-slope is required (or --fit FIT.json)")
        if args.band_index == "sampled":
            if args.material is None:
                raise UsageError("--band-index applies to --material (--n/--k are given per band)")
            bands = choose_bands(index_spectrum(args.material), bands, "sampled")
        return dict(rms_slope=args.rms_slope, n=None if args.n is None else _floats(args.n, "n"),
                    k=None if args.k is None else _floats(args.k, "k"), material=args.material,
                    shadowing=args.shadowing, diffuse=args.diffuse or RENDER_DEFAULT[1], diffuse_reflectance=albedo,
                    bands=bands)
    named = [f for f, v in (("--rms-slope", args.rms_slope), ("--material", args.material), ("--n", args.n),
                            ("--k", args.k), ("--diffuse", args.diffuse), ("--diffuse-reflectance", albedo),
                            ("--band-index", None if args.band_index == BAND_INDEX[0] else args.band_index))
             if v is not None]
    if named:
        raise UsageError(f"--fit gives the material: drop {', '.join(named)}")
    bands = KAIST_WAVELENGTHS if bands is None else bands
    with user_input(f"--fit {args.fit!r}"):
        result = json.loads(read_input(args.fit, "fit result (--fit)"))
        m = material_at(result, bands, extrapolate=args.extrapolate)
    if m["extrapolated"]:
        warnings.warn(f"--extrapolate: the fit was measured at {', '.join(f'{w:g}' for w in m['measured_nm']) or 'no stated'}"
                      f" nm; at {', '.join(f'{w:g}' for w in m['extrapolated'])} nm the nearest measured index is held "
                      "(a guess, not a measurement)", UserWarning, stacklevel=2)
    return dict(rms_slope=m["rms_slope"], n=m["n"], k=m["k"], shadowing=m["shadowing"], diffuse=m["diffuse"],
                diffuse_reflectance=m["diffuse_reflectance"], bands=bands)


def build_parser() -> Parser:
    ap = Parser(prog="hyde-bsdf export",
                 description="Write the hyde model as a Mitsuba measured_polarized table (.pbsdf) that the C++ "
                             "renderer (mitsuba executable, CUDA without Python) renders in *_spectral_polarized "
                             "variants; prints the measured interpolation error and the <bsdf> element to use. "
                             "Index: the paper's eta = n - jk (the plugin's eta = n, k = k).")
    writes(ap.add_argument("output", help="the .pbsdf file to write (atomically)"))
    ap.add_argument("--rms-slope", type=float, default=None,
                    help="the paper's rms_slope = sqrt(2) sigma_h/ell (required unless --fit)")
    reads(ap.add_argument("--fit", default=None, metavar="FIT.json",
                          help="the material of a fit's JSON result (hyde-bsdf fit --json): roughness, terms, albedo "
                               "and the index per wavelength, interpolated at the bands"))
    ap.add_argument("--extrapolate", action="store_true",
                    help="with --fit: hold the nearest measured index at bands outside the fit's wavelengths (a guess; "
                         "warned) instead of refusing")
    ap.add_argument("--material", default=None, help="a Mitsuba data/ior material (Au, Ag, Al, Cu, ...)")
    ap.add_argument("--n", default=None, help="real part of the index: one value or 5 (one per band)")
    ap.add_argument("--k", default=None, help="imaginary part (paper's kappa >= 0): one value or 5")
    ap.add_argument("--shadowing", default=RENDER_DEFAULT[0], choices=SHADOWING,
                    help="shadowing-masking: the paper's V-groove, Smith's for Beckmann, or none (default %(default)s)")
    ap.add_argument("--diffuse", default=None, choices=DIFFUSE,
                    help=f"diffuse term (default {RENDER_DEFAULT[1]}: the plugin's default, which conserves energy in a "
                         f"path tracer); paper: Eq. 17 as written, which gains energy at grazing angles there "
                         f"(docs/plugin.md); none; or a Lambertian term with its own albedo")
    ap.add_argument("--diffuse-reflectance", default=None,
                    help="the Lambertian term's albedo: one value or 5 (one per band); required with --diffuse lambertian")
    ap.add_argument("--resolution", default="x".join(map(str, DEFAULT_RESOLUTION)),
                    help="N_phi_d x N_theta_d x N_theta_h (default %(default)s)")
    ap.add_argument("--error-samples", type=int, default=20000,
                    help="geometries for the interpolation-error estimate (0: skip; default %(default)s)")
    ap.add_argument("--alpha-sample", type=float, default=None, help="override the suggested alpha_sample")
    ap.add_argument("--wavelengths", default="auto",
                    help="the 5 band wavelengths in nm (Mitsuba's loader reads exactly 5), e.g. 450,500,550,600,650; "
                         "auto (default): chosen for --material by the colour error they cause, 450-650 for --n/--k "
                         "and --fit")
    ap.add_argument("--band-index", default=BAND_INDEX[0], choices=BAND_INDEX,
                    help="a --material's index per band: the colour-weighted projection of its spectrum (default) "
                         "or the tabulated index sampled at the band wavelengths")
    quiet_option(ap)
    return ap


def cli_main(argv=None) -> int:
    """``hyde-bsdf export``: write the table, print the summary and the XML element."""
    parser = build_parser()
    args = parser.parse_args(argv)
    with user_input():
        check_not_input([args.output], run_inputs(parser, args), "the .pbsdf output")    # --fit FIT.json
        opts = _material(args)
        report = export_pbsdf(args.output, **opts, resolution=args.resolution,
                              error_samples=args.error_samples, alpha_sample=args.alpha_sample,
                              progress=False if args.quiet else stderr_lines())
    print(report.summary())
    print("\nMitsuba material (C++ measured_polarized, *_spectral_polarized variants):")
    print(report.xml(indent="    "))
    return 0
