"""A material's index over the wavelengths it was measured at, as Mitsuba's XML takes it, and what a
renderer does elsewhere: the ``hyde`` snippets of a lab fit (:mod:`hyde_bsdf.fit.lab`) and of a table
fit (:mod:`hyde_bsdf.fit.pbsdf_fit`).

Mitsuba reads a ``<spectrum name=... value="w:v, ...">`` as 0 outside its wavelengths in spectral
variants (the plugin then takes the index as 1 and reflects nothing, with a warning at load), and
integrates it over its colour range (:data:`RENDER_RANGE_NM`) in RGB variants: a spectrum given at
450-650 nm only renders black below and above in spectral variants and the wrong colour in RGB ones
(a constant 0.5 becomes the RGB index (0.42, 0.53, 0.25)).  So a spectrum whose measured wavelengths
end inside that range is written with its end values held out to 360 and 830 nm -- an explicit
extrapolation, said in the snippet's comment (:func:`wavelength_note`) and in a warning
(:func:`extrapolation_warning`), never silent.
"""
from __future__ import annotations

__all__ = ["RENDER_RANGE_NM", "spectrum_element", "wavelength_note", "extrapolation_warning"]

#: the wavelengths Mitsuba's spectral variants render and its RGB variants integrate over (nm)
RENDER_RANGE_NM = (360.0, 830.0)


def spectrum_element(name, wavelengths, values) -> str:
    """A float (one value, or the same at every wavelength) or a spectrum of wavelength:value pairs at
    the measured wavelengths, the end values held out to :data:`RENDER_RANGE_NM` where the measured
    range ends inside it (module docstring)."""
    if len(values) == 1 or all(v == values[0] for v in values):
        return f'<float name="{name}" value="{values[0]:.6g}"/>'
    pts = sorted(zip(wavelengths, values))
    if pts[0][0] > RENDER_RANGE_NM[0]:
        pts.insert(0, (RENDER_RANGE_NM[0], pts[0][1]))
    if pts[-1][0] < RENDER_RANGE_NM[1]:
        pts.append((RENDER_RANGE_NM[1], pts[-1][1]))
    return f'<spectrum name="{name}" value="{", ".join(f"{w:g}:{v:.6g}" for w, v in pts)}"/>'


def _held(lo, hi) -> str:
    """The ranges of Mitsuba's colour range where the end values are held, or ''."""
    parts = ([f"{RENDER_RANGE_NM[0]:g}-{lo:g}"] if lo > RENDER_RANGE_NM[0] else []) + \
            ([f"{hi:g}-{RENDER_RANGE_NM[1]:g}"] if hi < RENDER_RANGE_NM[1] else [])
    return " and ".join(parts)


def wavelength_note(wavelengths) -> str:
    """Where the material was measured, and what a renderer does elsewhere."""
    if wavelengths == [None]:
        return ("the data give no wavelength: this index holds at the wavelength it was measured at, "
                "and a renderer uses it at every wavelength")
    lo, hi = min(wavelengths), max(wavelengths)
    if len(wavelengths) == 1:
        return (f"measured at {lo:g} nm only: the index holds there; Mitsuba uses it at every rendered wavelength "
                f"({RENDER_RANGE_NM[0]:g}-{RENDER_RANGE_NM[1]:g} nm in spectral variants), where it was not measured")
    held = _held(lo, hi)
    out = "" if not held else (f"; over {held} nm the end values are held (an extrapolation, not measured: "
                               "Mitsuba's spectral variants render there and its RGB variants integrate over "
                               f"{RENDER_RANGE_NM[0]:g}-{RENDER_RANGE_NM[1]:g} nm)")
    return f"measured at {', '.join(f'{w:g}' for w in wavelengths)} nm, interpolated linearly between" + out


def extrapolation_warning(wavelengths) -> str | None:
    """The warning for a material measured at one wavelength (or none stated), or not over all of
    Mitsuba's 360-830 nm (its end values held there); None when its wavelengths span that range."""
    if wavelengths == [None] or len(wavelengths) == 1:
        return "the exported material: " + wavelength_note(wavelengths)
    if min(wavelengths) > RENDER_RANGE_NM[0] or max(wavelengths) < RENDER_RANGE_NM[1]:
        return "the exported material: " + wavelength_note(wavelengths).split("; ", 1)[1]
    return None
