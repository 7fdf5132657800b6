"""``hyde-bsdf render``: a scene to a Stokes EXR and PNG charts (:func:`hyde_bsdf.render.render_stokes`).

Command line::

    hyde-bsdf render SCENE.xml -o OUT.exr [--variant V] [--spp N] [--seed S]
                     [--chunks C] [-D name=value ...] [--no-png]

writes ``OUT.exr`` (channels R, G, B, S0.R ... S3.B, float32) and
``OUT_intensity.png``, ``OUT_dolp.png``, ``OUT_aolp.png``, ``OUT_docp.png``,
``OUT_rgb.png``; with an unpolarized variant ``OUT.exr`` (R, G, B) and ``OUT_rgb.png``.
Every output path is checked before the render starts (a name too long for the file system
included), and once the scene is loaded, before the first pass, the folder's free space against
an upper bound of what the set takes (:func:`output_bytes`): a full disk is refused with one line
naming -o and the bytes needed and free, not after the render.  Each file is written to a hidden
temporary and renamed over the old one when complete (:mod:`hyde_bsdf.io.atomic`), the EXR first:
a full disk or a failed write leaves that file as it was, no temporary, and ends in one line
naming the file (exit 2).
"""
from __future__ import annotations

import argparse
from pathlib import Path

from hyde_bsdf.app.args import Parser, positive_int, quiet_option, reads, run_inputs, writes
from hyde_bsdf.app.pictures import chart_bytes, polarization_png_paths, save_polarization_pngs, save_rgb_png
from hyde_bsdf.errors import UsageError, shorten
from hyde_bsdf.io.input_gate import check_input
from hyde_bsdf.io.output_gate import check_free_space, check_output_path, output_gate
from hyde_bsdf.io.stokes_exr import COLOURS, exr_bytes, exr_channel_names, write_stokes_exr
from hyde_bsdf.progress import stderr_lines
from hyde_bsdf.render.renderer import DEFAULT_VARIANT, MAX_SEED, render_stokes

__all__ = ["build_parser", "check_outputs", "output_bytes", "room_for", "cli_main"]

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
    reads(p.add_argument("scene", help="Mitsuba 3 scene (.xml)"), "scene")
    writes(p.add_argument("-o", "--output", required=True, help="output EXR path (must end in .exr)"))
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


def output_bytes(width: int, height: int, polarized: bool, png: bool = True) -> int:
    """Upper bound of the bytes ``render`` writes for a ``width`` x ``height`` film: the EXR
    (float32 channels, :func:`~hyde_bsdf.io.stokes_exr.exr_bytes`) and, with ``png``, each chart
    (:func:`~hyde_bsdf.app.pictures.chart_bytes`): what the folder must have free."""
    channels = len(exr_channel_names()) if polarized else len(COLOURS)
    charts = len(polarization_png_paths("out", polarized)) if png else 0
    return exr_bytes(width, height, channels) + charts * chart_bytes(width, height)


def room_for(folder, what: str, bytes_of, option: str = "free some space or choose another folder (-o)"):
    """A ``before_passes`` for :func:`~hyde_bsdf.render.renderer.render_stokes`: the output gate's
    free-space check of ``folder`` for ``bytes_of(width, height, polarized)`` bytes, run once the
    film size is known and before the first pass; its refusal names ``what`` and the film."""
    def check(width: int, height: int, polarized: bool) -> None:
        check_free_space(folder, bytes_of(width, height, polarized), f"{what} ({width}x{height} film)", option)
    return check


def _run(args, parser) -> int:
    out = Path(args.output)
    polarized = str(args.variant).endswith("_polarized")
    paths = check_outputs(out, polarized, png=not args.no_png)
    check_input(args.scene, "scene file", stdin=False)      # the input gate, before any work
    inputs = run_inputs(parser, args, dict(args.define))
    # the output gate: no output is an input of this run; one writer per output set at a time
    with output_gate(paths, inputs=inputs, what="render output"):
        return _render_and_write(args, out)


def _render_and_write(args, out: Path) -> int:
    result = render_stokes(args.scene, variant=args.variant, spp=args.spp, seed=args.seed,
                           chunks=args.chunks, params=dict(args.define), progress=_log,
                           before_passes=room_for(out.parent, f"-o {shorten(str(out))}",
                                                  lambda w, h, pol: output_bytes(w, h, pol, not args.no_png)))
    meta = result["meta"]
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
    parser = build_parser()
    return _run(parser.parse_args(argv), parser)
