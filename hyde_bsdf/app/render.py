"""``hyde-bsdf render``: a scene to a Stokes EXR and PNG charts (:func:`hyde_bsdf.render.render_stokes`).

Command line::

    hyde-bsdf render SCENE.xml -o OUT.exr [--variant V] [--spp N] [--seed S]
                     [--chunks C] [-D name=value ...] [--no-png]

writes ``OUT.exr`` (channels R, G, B, S0.R ... S3.B, float32) and
``OUT_intensity.png``, ``OUT_dolp.png``, ``OUT_aolp.png``, ``OUT_docp.png``,
``OUT_rgb.png``; with an unpolarized variant ``OUT.exr`` (R, G, B) and ``OUT_rgb.png``.
Every output path is checked before the render starts (a name too long for the file system
included).  The files are written as one set (:func:`hyde_bsdf.io.atomic.atomic_group`): each to a
hidden temporary, renamed only when every write has succeeded, so a full disk or a failed write
leaves the previous EXR and PNGs complete and consistent and ends in one line naming the file
(exit 2).
"""
from __future__ import annotations

import argparse
from pathlib import Path

from hyde_bsdf.app.args import Parser, positive_int, quiet_option
from hyde_bsdf.app.pictures import polarization_png_paths, save_polarization_pngs, save_rgb_png
from hyde_bsdf.errors import UsageError, shorten
from hyde_bsdf.io.atomic import atomic_group, check_output_path
from hyde_bsdf.io.stokes_exr import write_stokes_exr
from hyde_bsdf.progress import stderr_lines
from hyde_bsdf.render.renderer import DEFAULT_VARIANT, MAX_SEED, render_stokes

__all__ = ["build_parser", "check_outputs", "cli_main"]

_log = stderr_lines("[render]")


def _parse_define(text: str) -> tuple[str, str]:
    if "=" not in text or not text.split("=", 1)[0].strip():
        raise argparse.ArgumentTypeError(f"-D expects name=value, got {text!r}")
    name, value = text.split("=", 1)
    return name.strip(), value.strip()


def build_parser() -> Parser:
    p = Parser(
        prog="hyde-bsdf render",
        description="Render a Mitsuba scene to a Stokes EXR (R,G,B,S0.R..S3.B, float32) and PNG "
                    "charts of intensity, DoLP, AoLP and DoCP.  The scene may use the 'hyde' BSDF.  "
                    "An unpolarized --variant writes the colour image only.")
    p.add_argument("scene", help="Mitsuba 3 scene (.xml)")
    p.add_argument("-o", "--output", required=True, help="output EXR path (must end in .exr)")
    p.add_argument("--variant", default=DEFAULT_VARIANT,
                   help=f"Mitsuba variant (default {DEFAULT_VARIANT}; falls back to "
                        "scalar_spectral_polarized without a usable libLLVM); unpolarized variants "
                        "(llvm_ad_rgb, scalar_rgb, ...) write the colour image only")
    p.add_argument("--spp", type=positive_int, default=None,
                   help="samples per pixel (default: the scene's sampler)")
    p.add_argument("--seed", type=int, default=0, help=f"random seed, 0..{MAX_SEED} (default 0)")
    p.add_argument("--chunks", type=positive_int, default=None,
                   help="render in at least this many spp chunks (progress + error estimate; "
                        "default min(spp, 8))")
    p.add_argument("-D", dest="define", action="append", type=_parse_define, default=[],
                   metavar="NAME=VALUE", help="set a $NAME default of the scene (repeatable)")
    p.add_argument("--no-png", action="store_true", help="write only the EXR")
    quiet_option(p)
    return p


def check_outputs(out, polarized: bool, png: bool = True) -> list[Path]:
    """Check, before rendering, every file ``render`` will write for ``out`` (UsageError)."""
    out = Path(out)
    if out.suffix.lower() != ".exr":
        raise UsageError(f"--output must end in .exr, got {shorten(str(out))}")
    paths = [check_output_path(out, "--output")]
    if png:
        paths += [check_output_path(p, "PNG output") for p in polarization_png_paths(out.with_suffix(""),
                                                                                     polarized).values()]
    return paths


def _run(args) -> int:
    out = Path(args.output)
    polarized = str(args.variant).endswith("_polarized")
    check_outputs(out, polarized, png=not args.no_png)
    if not Path(args.scene).is_file():
        raise UsageError(f"scene file {shorten(args.scene)} does not exist")
    result = render_stokes(args.scene, variant=args.variant, spp=args.spp, seed=args.seed,
                           chunks=args.chunks, params=dict(args.define), progress=_log)
    meta = result["meta"]
    with atomic_group():      # the EXR and its PNGs replace the old set together, or not at all
        write_stokes_exr(out, result, metadata=meta)
        written = [out]
        if not args.no_png:
            stem = out.with_suffix("")
            title = Path(args.scene).stem
            if meta["polarized"]:
                written += list(save_polarization_pngs(result, stem, title=title).values())
            else:
                written.append(save_rgb_png(result["RGB"], polarization_png_paths(stem, False)["rgb"], title))
    _log(f"{meta['spp']} spp in {meta['seconds']:.1f} s ({meta['variant']}); wrote "
         + ", ".join(str(p) for p in written))
    return 0


def cli_main(argv=None) -> int:
    """``hyde-bsdf render``: 0 on success; a bad argument, input or output path raises
    :class:`~hyde_bsdf.errors.UsageError` (one line and exit 2 from :func:`hyde_bsdf.app.cli.main`)."""
    return _run(build_parser().parse_args(argv))
