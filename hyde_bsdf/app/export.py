"""``hyde-bsdf export``: the hyde model as a measured_polarized table (:func:`hyde_bsdf.fit.export_pbsdf`).

Command line::

    hyde-bsdf export OUT.pbsdf --rms-slope 0.3 (--material Au | --n N[,N,...] --k K[,K,...])
                     [--shadowing vgroove|smith|none] [--diffuse paper|reciprocal|none]
                     [--resolution 37x55x55] [--error-samples 20000]
                     [--wavelengths auto|W1,W2,W3,W4,W5] [--band-index projected|sampled] [-q]

prints the chosen bands and their colour error, the measured interpolation error and the ``<bsdf>``
element to use.
"""
from __future__ import annotations

from hyde_bsdf.app.args import Parser, quiet_option, user_input
from hyde_bsdf.errors import UsageError, shorten
from hyde_bsdf.fit.pbsdf_bands import BAND_INDEX, check_wavelengths, choose_bands, index_spectrum
from hyde_bsdf.fit.pbsdf_export import DEFAULT_RESOLUTION, export_pbsdf
from hyde_bsdf.model.terms import DIFFUSE, RENDER_DEFAULT, SHADOWING
from hyde_bsdf.progress import stderr_lines

__all__ = ["build_parser", "cli_main"]


def _floats(text, name):
    try:
        vals = [float(v) for v in str(text).split(",")]
    except ValueError:
        raise UsageError(f"--{name} must be a number or 5 comma-separated numbers (one per band), got {shorten(text)}") from None
    return vals[0] if len(vals) == 1 else vals


def build_parser() -> Parser:
    ap = Parser(prog="hyde-bsdf export",
                 description="Write the hyde model as a Mitsuba measured_polarized table (.pbsdf) that the C++ "
                             "renderer (mitsuba executable, CUDA without Python) renders in *_spectral_polarized "
                             "variants; prints the measured interpolation error and the <bsdf> element to use. "
                             "Index: the paper's eta = n - jk (the plugin's eta = n, k = k).")
    ap.add_argument("output", help="the .pbsdf file to write (atomically)")
    ap.add_argument("--rms-slope", type=float, required=True, help="the paper's rms_slope = sqrt(2) sigma_h/ell")
    ap.add_argument("--material", default=None, help="a Mitsuba data/ior material (Au, Ag, Al, Cu, ...)")
    ap.add_argument("--n", default=None, help="real part of the index: one value or 5 (450..650 nm)")
    ap.add_argument("--k", default=None, help="imaginary part (paper's kappa >= 0): one value or 5")
    ap.add_argument("--shadowing", default=RENDER_DEFAULT[0], choices=SHADOWING,
                    help="shadowing-masking: the paper's V-groove, Smith's for Beckmann, or none (default %(default)s)")
    ap.add_argument("--diffuse", default=RENDER_DEFAULT[1], choices=DIFFUSE,
                    help="diffuse term: the reciprocal form of the paper's (default: a table that conserves energy in "
                         "a path tracer, as the plugin's default), the paper's Eq. 17 (gains energy at grazing "
                         "angles in a path tracer: docs/plugin.md), none, ... (default %(default)s)")
    ap.add_argument("--resolution", default="x".join(map(str, DEFAULT_RESOLUTION)),
                    help="N_phi_d x N_theta_d x N_theta_h (default %(default)s)")
    ap.add_argument("--error-samples", type=int, default=20000,
                    help="geometries for the interpolation-error estimate (0: skip; default %(default)s)")
    ap.add_argument("--alpha-sample", type=float, default=None, help="override the suggested alpha_sample")
    ap.add_argument("--wavelengths", default="auto",
                    help="the 5 band wavelengths in nm (Mitsuba's loader reads exactly 5), e.g. 450,500,550,600,650; "
                         "auto (default): chosen for --material by the colour error they cause, 450-650 for --n/--k")
    ap.add_argument("--band-index", default="projected", choices=BAND_INDEX,
                    help="a --material's index per band: the colour-weighted projection of its spectrum (default) "
                         "or the tabulated index sampled at the band wavelengths")
    quiet_option(ap)
    return ap


def cli_main(argv=None) -> int:
    """``hyde-bsdf export``: write the table, print the summary and the XML element."""
    args = build_parser().parse_args(argv)
    n = None if args.n is None else _floats(args.n, "n")
    k = None if args.k is None else _floats(args.k, "k")
    with user_input():
        bands = None if args.wavelengths == "auto" else check_wavelengths(_floats(args.wavelengths, "wavelengths"))
        if args.band_index == "sampled":
            if args.material is None:
                raise UsageError("--band-index applies to --material (--n/--k are given per band)")
            bands = choose_bands(index_spectrum(args.material), bands, "sampled")
        report = export_pbsdf(args.output, rms_slope=args.rms_slope, n=n, k=k,
                              material=args.material,
                              shadowing=args.shadowing, diffuse=args.diffuse, resolution=args.resolution,
                              error_samples=args.error_samples, alpha_sample=args.alpha_sample,
                              progress=False if args.quiet else stderr_lines(), bands=bands)
    print(report.summary())
    print("\nMitsuba material (C++ measured_polarized, *_spectral_polarized variants):")
    print(report.xml(indent="    "))
    return 0
