"""``hyde-bsdf demo``: the main job -- render the demo scene with the ``hyde`` BSDF.

Renders ``hyde_bsdf/data/scenes/demo.xml`` (a gold and an aluminium sphere and an aluminium
cylinder on a rough dark-glass floor, low sun, dim sky) with Mitsuba's
``stokes`` integrator in ``llvm_ad_spectral_polarized`` (falling back to
``scalar_spectral_polarized`` with a message when no usable libLLVM is present)
and writes into the output folder:

``demo.exr``            Stokes EXR: R, G, B, S0.R ... S3.B (float32, sensor basis)
``demo_intensity.png``  S0 (luminance) with a colour bar
``demo_dolp.png``       degree of linear polarization
``demo_aolp.png``       angle of linear polarization (from the image horizontal)
``demo_docp.png``       degree of circular polarization (signed)
``demo_rgb.png``        the colour picture
``demo_overview.png``   the colour picture, DoLP, AoLP and DoCP side by side

With an unpolarized ``--variant`` (``llvm_ad_rgb``, ...) only ``demo.exr`` (R, G, B) and
``demo_rgb.png`` are written.  The output folder and every file in it are checked before the
render starts; each file replaces its old version only once it is complete
(:mod:`hyde_bsdf.io.atomic`), so a full disk leaves the file it stopped at as it was.  Once the picture's size is known, before the first pass, the folder's free space is
checked against an upper bound of the set's size (:func:`demo_bytes`).

The default (448 x 280 pixels, 96 spp) takes ~15-20 s on 2 cores with the LLVM
variant; ``--width/--height/--spp`` raise it.  On the scalar fallback (one
Python call per BSDF query, ~3000 samples/s) the defaults drop to 128 x 80
pixels, 8 spp (~30 s) unless given explicitly.
"""
from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from hyde_bsdf.app.args import Parser, positive_int, quiet_option, reads, writes
from hyde_bsdf.app.pictures import (png_bytes, polarization_png_paths, save_png, save_polarization_pngs,
                                    save_rgb_png)
from hyde_bsdf.app.render import output_bytes, room_for
from hyde_bsdf.errors import UsageError, shorten
from hyde_bsdf.io.input_gate import check_input
from hyde_bsdf.io.output_gate import check_output_dir, check_output_path, output_gate
from hyde_bsdf.io.scene_files import scene_files
from hyde_bsdf.io.stokes_exr import write_stokes_exr
from hyde_bsdf.progress import stderr_lines
from hyde_bsdf.render.polarization import polarization_quantities, tonemap
from hyde_bsdf.render.renderer import DEFAULT_VARIANT, prepare_variant, render_stokes

__all__ = ["DEMO_SCENE", "cli_main", "render_demo", "demo_bytes"]

#: The demo scene, shipped with the package (hyde_bsdf/data/scenes/, beside the other example scenes).
DEMO_SCENE = Path(__file__).resolve().parents[1] / "data" / "scenes" / "demo.xml"


_log = stderr_lines("[demo]")


#: Default picture size and samples: (width, height, spp) for LLVM and for the scalar fallback.
DEFAULTS_LLVM = (448, 280, 96)
DEFAULTS_SCALAR = (128, 80, 8)


def render_demo(outdir, width=None, height=None, spp=None, variant=DEFAULT_VARIANT, seed=0,
                bsdf="hyde", scene=DEMO_SCENE) -> dict:
    """Render the demo scene and write its EXR and PNGs into ``outdir``; returns {name: path}.

    ``width``, ``height``, ``spp`` left as None take :data:`DEFAULTS_LLVM`, or the smaller
    :data:`DEFAULTS_SCALAR` when the variant falls back to scalar.  One run at a time writes the
    set (the output gate's lock): a second fails at once with one line.
    """
    if bsdf not in ("hyde", "roughconductor"):
        raise UsageError(f"bsdf must be 'hyde' or 'roughconductor', got {bsdf!r}")
    scene = Path(scene)
    if not scene.exists():
        raise UsageError(f"demo scene {str(scene)!r} not found: pass --scene")
    check_input(scene, "demo scene", stdin=False)          # a FIFO or a device: one line, never opened
    outdir = check_output_dir(outdir, "--outdir")
    outputs = [check_output_path(p, "output file") for p in demo_outputs(outdir, str(variant).endswith("_polarized"))]
    with output_gate(outputs, inputs=scene_files(scene), what="demo output"):
        return _render_demo(outdir, width, height, spp, variant, seed, bsdf, scene)


def _render_demo(outdir, width, height, spp, variant, seed, bsdf, scene) -> dict:
    chosen = prepare_variant(variant)
    defaults = DEFAULTS_SCALAR if chosen.startswith("scalar_") else DEFAULTS_LLVM
    if chosen.startswith("scalar_") and None in (width, height, spp):
        _log("scalar variant: using a smaller default picture (%dx%d px, %d spp); "
             "pass --width/--height/--spp to override" % DEFAULTS_SCALAR)
    width, height, spp = (d if v is None else v for v, d in zip((width, height, spp), defaults))
    if bsdf == "hyde":
        import mitsuba as mi

        if "hyde" not in _registered_plugins(mi):
            raise UsageError("the 'hyde' BSDF plugin is not available in this installation "
                             "(hyde_bsdf/plugin.py); use --bsdf roughconductor to render the scene "
                             "with Mitsuba's microfacet conductor instead")
    _log(f"rendering {scene.name} with the '{bsdf}' BSDF, {width}x{height} px, {spp} spp, "
         f"variant {chosen}")
    params = {"width": width, "height": height, "spp": spp, "conductor": bsdf, "floor": bsdf}
    result = render_stokes(scene, variant=chosen, spp=spp, seed=seed, params=params,
                           progress=stderr_lines("[render]"),
                           before_passes=room_for(outdir, f"-o {shorten(str(outdir))}", demo_bytes,
                                                  "free some space, choose another folder (-o) or "
                                                  "lower --width/--height"))
    meta = dict(result["meta"], bsdf=bsdf, scene=scene.name)
    paths = {"exr": write_stokes_exr(outdir / "demo.exr", result, metadata=meta)}
    title = f"demo ({bsdf})"
    if meta["polarized"]:
        paths.update(save_polarization_pngs(result, outdir / "demo", title=title))
        paths["overview"] = _overview(result, outdir / "demo_overview.png", title)
    else:
        paths["rgb"] = save_rgb_png(result["RGB"], outdir / "demo_rgb.png", title)
    _log(f"{meta['spp']} spp in {meta['seconds']:.1f} s; wrote " + ", ".join(str(p) for p in paths.values()))
    return paths


def demo_outputs(outdir, polarized: bool = True) -> list[Path]:
    """The files :func:`render_demo` writes into ``outdir``."""
    outdir = Path(outdir)
    files = [outdir / "demo.exr", *polarization_png_paths(outdir / "demo", polarized).values()]
    return files + ([outdir / "demo_overview.png"] if polarized else [])


def _registered_plugins(mi) -> set:
    """Whether the hyde plugin can be instantiated in the current variant."""
    try:
        mi.load_dict({"type": "hyde"})
    except Exception:
        return set()
    return {"hyde"}


#: the overview's resolution (dots per inch)
OVERVIEW_DPI = 100


def _overview_inches(height: int, width: int) -> tuple[float, float]:
    """(width, height) in inches of the overview of a ``height`` x ``width`` picture (2 x 2 panels)."""
    return 12, 12 * height / width + 1.2


def demo_bytes(width: int, height: int, polarized: bool = True) -> int:
    """Upper bound of the bytes the demo writes for a ``width`` x ``height`` picture: ``render``'s
    set (:func:`~hyde_bsdf.app.render.output_bytes`) and, polarized, the overview PNG."""
    overview = png_bytes(*_overview_inches(height, width), OVERVIEW_DPI) if polarized else 0
    return output_bytes(width, height, polarized) + overview


def _overview(stokes: dict, path: Path, title: str) -> Path:
    """One PNG with the colour picture, DoLP, AoLP and DoCP side by side (with colour bars)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    q = polarization_quantities(stokes)
    valid = q["valid"]
    h, w = valid.shape
    fig, axes = plt.subplots(2, 2, figsize=_overview_inches(h, w), dpi=OVERVIEW_DPI)
    ax = axes[0, 0]
    ax.imshow(tonemap(stokes["RGB"]))
    ax.set_title("colour (sRGB)")
    panels = [
        (axes[0, 1], np.ma.masked_where(~valid, q["dolp"]), "viridis", 0, 1, "DoLP"),
        (axes[1, 0], np.ma.masked_where(~valid | (q["dolp"] < 0.01), np.degrees(q["aolp"])),
         "twilight", -90, 90, "AoLP (deg from horizontal; grey: DoLP < 0.01)"),
    ]
    docp = q["docp"]
    lim = float(np.percentile(np.abs(docp[valid]), 99.5)) if np.any(valid) else 1.0
    lim = min(max(lim, 1e-3), 1.0)  # visible range even when S3 ~ 0
    panels.append((axes[1, 1], np.ma.masked_where(~valid, docp), "RdBu_r", -lim, lim, "DoCP = S3/S0"))
    for ax, data, cmap, lo, hi, name in panels:
        cm = matplotlib.colormaps[cmap].with_extremes(bad="0.5")
        im = ax.imshow(data, cmap=cm, vmin=lo, vmax=hi, interpolation="nearest")
        fig.colorbar(im, ax=ax, fraction=0.046, pad=0.02)
        ax.set_title(name)
    for ax in axes.ravel():
        ax.set_xticks([])
        ax.set_yticks([])
    fig.suptitle(title)
    fig.tight_layout()
    save_png(fig, path)
    return path


def build_parser() -> Parser:
    p = Parser(prog="hyde-bsdf demo", description=__doc__.split("\n\n")[0])
    writes(p.add_argument("-o", "--outdir", default="out/demo", help="output folder (default out/demo)"))
    p.add_argument("--width", type=positive_int, default=None,
                   help="image width in pixels (default %d; %d on the scalar fallback)"
                   % (DEFAULTS_LLVM[0], DEFAULTS_SCALAR[0]))
    p.add_argument("--height", type=positive_int, default=None,
                   help="image height in pixels (default %d; %d on the scalar fallback)"
                   % (DEFAULTS_LLVM[1], DEFAULTS_SCALAR[1]))
    p.add_argument("--spp", type=positive_int, default=None,
                   help="samples per pixel (default %d; %d on the scalar fallback)"
                   % (DEFAULTS_LLVM[2], DEFAULTS_SCALAR[2]))
    p.add_argument("--variant", default=DEFAULT_VARIANT,
                   help=f"Mitsuba variant (default {DEFAULT_VARIANT}; an unpolarized one writes "
                        "the colour image only)")
    p.add_argument("--seed", type=int, default=0, help="random seed 0..32767 (default 0)")
    p.add_argument("--bsdf", choices=("hyde", "roughconductor"), default="hyde",
                   help="BSDF of the metals and the floor (default hyde; roughconductor to compare)")
    reads(p.add_argument("--scene", default=str(DEMO_SCENE),
                         help="scene file (default hyde_bsdf/data/scenes/demo.xml)"), "scene")
    quiet_option(p)
    return p


def cli_main(argv=None) -> int:
    """``hyde-bsdf demo -o OUTDIR``: 0 on success; user errors raise UsageError (exit 2)."""
    args = build_parser().parse_args(argv)
    t0 = time.perf_counter()
    render_demo(args.outdir, args.width, args.height, args.spp, args.variant, args.seed, args.bsdf, args.scene)
    _log(f"done in {time.perf_counter() - t0:.1f} s")
    return 0
