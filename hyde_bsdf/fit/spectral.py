"""A material's index over the wavelengths it was measured at, as Mitsuba's XML takes it, and what a
renderer does elsewhere: the ``hyde`` snippets of a lab fit (:mod:`hyde_bsdf.fit.lab`) and of a table
fit (:mod:`hyde_bsdf.fit.pbsdf_fit`) carry the measured wavelengths only -- never values held or
extrapolated beyond them -- and say (a comment, a warning) where the renderer will use them unmeasured.
"""
from __future__ import annotations

__all__ = ["RENDER_RANGE_NM", "spectrum_element", "wavelength_note", "extrapolation_warning"]

#: the wavelengths Mitsuba's spectral variants render (nm): an index measured elsewhere is extrapolated there
RENDER_RANGE_NM = (360.0, 830.0)


def spectrum_element(name, wavelengths, values) -> str:
    """A float (one value, or the same at every wavelength) or a spectrum of wavelength:value pairs."""
    if len(values) == 1 or all(v == values[0] for v in values):
        return f'<float name="{name}" value="{values[0]:.6g}"/>'
    pairs = ", ".join(f"{w:g}:{v:.6g}" for w, v in zip(wavelengths, values))
    return f'<spectrum name="{name}" value="{pairs}"/>'


def wavelength_note(wavelengths) -> str:
    """Where the material was measured, and what a renderer does elsewhere."""
    if wavelengths == [None]:
        return ("the data give no wavelength: this index holds at the wavelength it was measured at, "
                "and a renderer uses it at every wavelength")
    lo, hi = min(wavelengths), max(wavelengths)
    if len(wavelengths) == 1:
        return (f"measured at {lo:g} nm only: the index holds there; Mitsuba uses it at every rendered wavelength "
                f"({RENDER_RANGE_NM[0]:g}-{RENDER_RANGE_NM[1]:g} nm in spectral variants), where it was not measured")
    out = "" if lo <= RENDER_RANGE_NM[0] and hi >= RENDER_RANGE_NM[1] else (
        f"; outside {lo:g}-{hi:g} nm Mitsuba reads these spectra as 0, where the plugin reflects nothing (and warns)")
    return f"measured at {', '.join(f'{w:g}' for w in wavelengths)} nm, interpolated linearly between" + out


def extrapolation_warning(wavelengths) -> str | None:
    """The warning for a material measured at one wavelength (or none stated), or outside the
    rendered range; None when its wavelengths span Mitsuba's 360-830 nm."""
    if wavelengths == [None] or len(wavelengths) == 1:
        return "the exported material: " + wavelength_note(wavelengths)
    if min(wavelengths) > RENDER_RANGE_NM[0] or max(wavelengths) < RENDER_RANGE_NM[1]:
        return "the exported material: " + wavelength_note(wavelengths).split("; ", 1)[1]
    return None
