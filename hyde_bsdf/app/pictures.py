"""PNG charts of a Stokes image: intensity, DoLP, AoLP, DoCP and the colour image (matplotlib).

The quantities come from :mod:`hyde_bsdf.render.polarization`; every PNG is written atomically
(:mod:`hyde_bsdf.io.atomic`).  Used by ``hyde-bsdf render``, ``hyde-bsdf demo`` and the
validation scripts.
"""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from hyde_bsdf.io.atomic import atomic_path
from hyde_bsdf.render.polarization import polarization_quantities, tonemap

__all__ = ["save_polarization_pngs", "save_rgb_png", "polarization_png_paths", "save_png", "png_bytes",
           "chart_bytes", "CHART_DPI"]

#: the charts' resolution, dots per inch
CHART_DPI = 110
#: the charts' width, inches (the height follows the image's aspect)
CHART_WIDTH = 6.4


def _chart_inches(height: int, width: int) -> tuple[float, float]:
    """(width, height) in inches of the chart of a ``height`` x ``width`` image."""
    return CHART_WIDTH, max(2.4, CHART_WIDTH * height / width * 0.85 + 0.6)


def png_bytes(width_in: float, height_in: float, dpi: float) -> int:
    """Upper bound of the size of a matplotlib figure of ``width_in`` x ``height_in`` inches saved
    as PNG at ``dpi``: its pixels as uncompressed RGBA, one filter byte per row, zlib's worst case
    (0.1 %) and 64 KiB for the chunks and the text.  What the output gate's free-space check is
    given (a chart of a smooth image compresses 10-50 times)."""
    w, h = math.ceil(width_in * dpi), math.ceil(height_in * dpi)
    raw = h * (4 * w + 1)
    return raw + raw // 1000 + (1 << 16)


def chart_bytes(width: int, height: int) -> int:
    """Upper bound of the size of one chart (:func:`save_polarization_pngs`, :func:`save_rgb_png`)
    of a ``width`` x ``height`` image (:func:`png_bytes`)."""
    return png_bytes(*_chart_inches(height, width), CHART_DPI)


def save_polarization_pngs(stokes: dict, stem, title: str = "", channel: str = "Y",
                           dolp_mask: float = 0.01, charts=None) -> dict[str, Path]:
    """Write the four polarization charts (plus a colour image) as PNGs with colour bars.

    Files: ``{stem}_intensity.png`` (S0, inferno on a square-root scale, clipped at the
    99.5th percentile),
    ``{stem}_dolp.png`` (viridis, [0, 1]), ``{stem}_aolp.png`` (cyclic ``twilight``,
    [-90, 90] deg, grey where DoLP < ``dolp_mask`` or no light), ``{stem}_docp.png``
    (diverging, symmetric range), and ``{stem}_rgb.png`` (the colour image, sRGB).
    ``charts``: the names to write (default all five; a linear-only camera's data: intensity, dolp, aolp).
    Returns {name: path}.
    """
    import matplotlib

    matplotlib.use("Agg")
    stem = Path(stem)
    stem.parent.mkdir(parents=True, exist_ok=True)
    q = polarization_quantities(stokes, channel)
    valid = q["valid"]
    label = {"Y": "luminance", "R": "red channel", "G": "green channel", "B": "blue channel"}[channel]
    prefix = f"{title}: " if title else ""
    paths: dict[str, Path] = {}

    def chart(name, data, cmap, vmin, vmax, cbar_label, heading, gamma=None):
        if charts is not None and name not in charts:
            return
        paths[name] = _chart(Path(f"{stem}_{name}.png"), data, cmap, vmin, vmax, cbar_label, prefix + heading, gamma)

    inten = q["intensity"]
    vmax = float(np.percentile(inten, 99.5)) if np.any(inten > 0) else 1.0
    vmax = vmax if vmax > 0 else 1.0
    # Square-root colour scale: highlights are orders of magnitude above the rest.
    chart("intensity", inten, "inferno", 0.0, vmax, f"S0 ({label}, scene radiance units; sqrt scale)",
          "intensity S0", gamma=0.5)
    chart("dolp", np.ma.masked_where(~valid, q["dolp"]), "viridis", 0.0, 1.0,
          "DoLP = sqrt(S1² + S2²) / S0", "degree of linear polarization")
    aolp_deg = np.degrees(q["aolp"])
    chart("aolp", np.ma.masked_where(~valid | (q["dolp"] < dolp_mask), aolp_deg), "twilight",
          -90.0, 90.0, "AoLP (deg, from image horizontal, counter-clockwise)",
          f"angle of linear polarization (grey: DoLP < {dolp_mask:g})")
    docp = q["docp"]
    lim = float(np.percentile(np.abs(docp[valid]), 99.5)) if np.any(valid) else 1.0
    lim = min(max(lim, 1e-3), 1.0)  # keep a visible range when S3 is ~0 everywhere
    chart("docp", np.ma.masked_where(~valid, docp), "RdBu_r", -lim, lim, "DoCP = S3 / S0",
          "degree of circular polarization")

    if charts is None or "rgb" in charts:
        paths["rgb"] = save_rgb_png(stokes.get("RGB", stokes["S0"]), Path(f"{stem}_rgb.png"), title)
    return paths


def _chart(path: Path, data, cmap, vmin, vmax, cbar_label, heading, gamma=None) -> Path:
    """One chart with a colour bar (grey where ``data`` is masked), written atomically."""
    import matplotlib
    import matplotlib.pyplot as plt

    h, w = data.shape
    fig, ax = plt.subplots(figsize=_chart_inches(h, w), dpi=CHART_DPI)
    cm = matplotlib.colormaps[cmap].with_extremes(bad="0.5")
    if gamma is None:
        im = ax.imshow(data, cmap=cm, vmin=vmin, vmax=vmax, interpolation="nearest")
    else:
        norm = matplotlib.colors.PowerNorm(gamma, vmin=vmin, vmax=vmax)
        im = ax.imshow(data, cmap=cm, norm=norm, interpolation="nearest")
    ax.set_title(heading, fontsize=10)
    ax.set_xticks([])
    ax.set_yticks([])
    cb = fig.colorbar(im, ax=ax, fraction=0.046, pad=0.03)
    cb.set_label(cbar_label)
    fig.tight_layout()
    save_png(fig, path)
    return path


def polarization_png_paths(stem, polarized: bool = True) -> dict[str, Path]:
    """The PNG files :func:`save_polarization_pngs` (or, unpolarized, :func:`save_rgb_png`)
    writes for ``stem``: {name: path}, so a command can check them before rendering."""
    names = ("intensity", "dolp", "aolp", "docp", "rgb") if polarized else ("rgb",)
    return {name: Path(f"{stem}_{name}.png") for name in names}


def save_png(fig, path: Path) -> None:
    """``fig.savefig`` as PNG through a temporary file (atomic), then close the figure."""
    import matplotlib.pyplot as plt

    try:
        with atomic_path(path) as tmp:
            fig.savefig(tmp, format="png")
    finally:
        plt.close(fig)


def save_rgb_png(rgb, path, title: str = "") -> Path:
    """The colour image (linear RGB (H, W, 3), clipped at 1, sRGB curve) as a PNG chart."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rgb = np.asarray(rgb)
    h, w = rgb.shape[:2]
    prefix = f"{title}: " if title else ""
    fig, ax = plt.subplots(figsize=_chart_inches(h, w), dpi=CHART_DPI)
    ax.imshow(tonemap(rgb), interpolation="nearest")
    ax.set_title(prefix + "colour image (sRGB, clipped at 1)", fontsize=10)
    ax.set_xticks([])
    ax.set_yticks([])
    fig.tight_layout()
    path = Path(path)
    save_png(fig, path)
    return path

