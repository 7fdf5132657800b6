"""The five wavelength bands of an exported ``measured_polarized`` table, chosen by the colour error.

Mitsuba's ``measured_polarized`` loader reads exactly five band wavelengths (``wvls``), interpolates
the table linearly in wavelength between them and clamps outside them.  A spectral render samples
wavelengths over Mitsuba's colour range [360, 830] nm and develops them into sRGB, so the five bands
decide the colour of the table's render: the table's spectrum is the piecewise-linear spectrum
through the bands, sum_b h_b(lambda) M_b (h_b the hat functions of the bands, the end ones flat
beyond the end bands), where the Python plugin renders the tabulated index at every wavelength.

**Colour.**  A white light of a spectral render has the D65 spectrum (Mitsuba's emitters upsample an
RGB value as rgb2spec x D65), so a reflectance spectrum R(lambda) develops into the linear sRGB
channels c = int w_c(lambda) R(lambda) d lambda with w_c = (XYZ -> sRGB) [x, y, z](lambda) D65(lambda) /
int y D65 -- Mitsuba's own CIE 1931 tables, D65 spectrum and sRGB matrix (:func:`colour_weights`).
In a table cell the spectrum enters through the facet Fresnel reflectance only: M00 = (geometry) x
A(beta; eta(lambda)) for the specular lobe and the paper's diffuse terms alike (beta = theta_d, the
Rusinkiewicz angle).  So the colour error of a band set is, per channel,

    e_c = max over beta of |int w_c [A_table(beta, lambda) - A(beta, lambda)] d lambda| / |int w_c A(beta, lambda)|

over beta = 0, 5, ..., 85, 88 deg, where A_table is the piecewise-linear spectrum through the band
values and A the reflectance of the index spectrum as the plugin renders it (Mitsuba's rule: a
tabulated spectrum is 0 outside its wavelengths, and an index with n = k = 0 reflects nothing).

**Band index.**  ``"projected"`` (default): the index of band b is the colour-weighted least-squares
projection of the index spectrum onto the hat functions, (n_b, k_b) minimizing
int omega(lambda) (sum_b h_b(lambda) x_b - x(lambda))^2 d lambda for x = n and x = k, omega = sum_c |w_c|:
the piecewise-linear index spectrum through the bands that is closest where the eye looks.  Each band
holds a real index (so every table cell is the Mueller matrix of a physical interface), not the
tabulated one at the band's wavelength.  ``"sampled"``: the tabulated index at the band wavelengths
(the KAIST convention; colour errors of several % for gold and copper).  Measured over Mitsuba's
``data/ior`` names (``docs/tutorials/pbsdf.md``): gold's largest channel error is 5.7 % with the index
sampled at 450-650 nm, 1.3 % with the best five sampled bands, 0.45 % with the projected index.

**Choice.**  Integer band wavelengths in [360, 830] nm (``wvls`` is uint16), increasing, chosen by
coordinate descent (steps 32 ... 1 nm, from three starting sets) to minimize the largest channel
error; :func:`choose_bands`.  About 0.5 s per material.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from functools import lru_cache

import numpy as np

from hyde_bsdf.errors import UsageError
from hyde_bsdf.io.ior import material_files
from hyde_bsdf.io.pbsdf_file import KAIST_WAVELENGTHS, MITSUBA_BANDS
from hyde_bsdf.model.fresnel import fresnel_mueller_terms
from hyde_bsdf.model.index import Index
from hyde_bsdf.model.parameters import INDEX_MIN

__all__ = ["COLOUR_RANGE", "BAND_INDEX", "COLOUR_TARGET", "BandChoice", "colour_weights", "index_spectrum",
           "colour_error", "projected_index", "check_wavelengths", "choose_bands"]

#: Mitsuba's colour range (MI_CIE_MIN, MI_CIE_MAX), nm: spectral renders sample wavelengths in it
COLOUR_RANGE = (360, 830)
#: how a band's index is taken from the index spectrum (module docstring)
BAND_INDEX = ("projected", "sampled")
#: the export's default promise: each sRGB channel of a render within 1 % of the Python plugin's
COLOUR_TARGET = 0.01
#: facet angles beta (deg) over which the colour error is taken
BETA_DEG = tuple(float(b) for b in np.concatenate([np.arange(0.0, 86.0, 5.0), [88.0]]))
#: starting band sets of the search: the KAIST bands, and two spread over the colour-matching functions
_STARTS = (KAIST_WAVELENGTHS, (440, 480, 530, 580, 640), (420, 470, 520, 590, 680))
_CHANNELS = ("R", "G", "B")


@lru_cache(maxsize=1)
def colour_weights():
    """(wavelengths (nm, 1-nm steps over :data:`COLOUR_RANGE`), W (L, 3)): the linear sRGB weight of each
    wavelength under a D65 white light, from Mitsuba's CIE 1931 tables, D65 spectrum and XYZ -> sRGB
    matrix; sum_lambda W[lambda, c] = 1 (a perfect white reflector renders (1, 1, 1))."""
    import mitsuba as mi

    m = mi.scalar_spectral      # the variant's functions, without selecting a variant
    wl = np.arange(COLOUR_RANGE[0], COLOUR_RANGE[1] + 1, dtype=float)
    xyz = np.array([list(m.cie1931_xyz(float(v))) for v in wl])
    d65 = np.array([float(m.cie_d65(float(v))) for v in wl])
    to_srgb = np.array([list(m.xyz_to_srgb(m.Color3f(*e))) for e in np.eye(3)]).T
    W = (xyz * d65[:, None]) @ to_srgb.T
    return wl, W / W.sum(axis=0)


def index_spectrum(material=None, wavelengths=None, n=None, k=None):
    """(wavelengths nm, n, k) of an index spectrum: a Mitsuba ``data/ior`` material's tables, or the
    given arrays (increasing wavelengths)."""
    if material is not None:
        tables = []
        for path in material_files(material):      # data/ior names only
            data = np.loadtxt(path, comments="#")
            tables.append(data)
        (wl_n, n), (wl_k, k) = (t.T for t in tables)
        wl = np.union1d(wl_n, wl_k)
        return wl, np.interp(wl, wl_n, n), np.interp(wl, wl_k, k)
    wl, n, k = (np.atleast_1d(np.asarray(v, float)) for v in (wavelengths, n, k))
    if not (wl.ndim == 1 and wl.shape == n.shape == k.shape and wl.size >= 1 and np.all(np.diff(wl) > 0)):
        raise UsageError("an index spectrum needs increasing wavelengths and one n and one k per wavelength")
    return wl, n, k


def _on_grid(spectrum, grid):
    """n, k of ``spectrum`` at the wavelengths ``grid``, as Mitsuba's spectra read them: linear between
    the tabulated wavelengths, 0 outside them."""
    wl, n, k = spectrum
    return (np.interp(grid, wl, n, left=0.0, right=0.0), np.interp(grid, wl, k, left=0.0, right=0.0))


def _reflectance(n, k, cos_beta):
    """A(beta; n - jk), the facet's unpolarized Fresnel reflectance (paper Eq. 11, M00), shape
    (len(n), len(cos_beta)); an index below INDEX_MIN is taken as 1 (no interface: the plugin's rule
    where a tabulated spectrum is 0)."""
    out = np.empty((len(n), len(cos_beta)))
    for i, (a, b) in enumerate(zip(n, k)):
        if math.hypot(a, b) < INDEX_MIN:
            out[i] = 0.0
        else:
            out[i] = fresnel_mueller_terms(cos_beta, Index(float(a), float(b)))[0]
    return out


def _hats(bands, grid):
    """(B, L): the hat functions of the band wavelengths on ``grid`` (Mitsuba's linear interpolation,
    clamped outside the end bands)."""
    return np.stack([np.interp(grid, bands, row) for row in np.eye(len(bands))])


def projected_index(spectrum, bands):
    """(n_b, k_b): the colour-weighted least-squares projection of the index spectrum onto the hat
    functions of ``bands`` (module docstring, "Band index")."""
    grid, W = colour_weights()
    omega = np.abs(W).sum(axis=1)
    H = _hats(np.asarray(bands, float), grid)
    gram = (H * omega) @ H.T
    n, k = _on_grid(spectrum, grid)
    # a least-squares fit may undershoot where the spectrum steps (a table ending inside the colour
    # range): an index is >= 0
    return tuple(np.maximum(np.linalg.solve(gram, (H * omega) @ x), 0.0) for x in (n, k))


def _truth(spectrum):
    """int w_c A(beta, lambda): the plugin's colour at each facet angle, (3, len(BETA_DEG))."""
    grid, W = colour_weights()
    return W.T @ _reflectance(*_on_grid(spectrum, grid), np.cos(np.radians(BETA_DEG)))


def colour_error(spectrum, bands, n_b, k_b, truth=None) -> np.ndarray:
    """The largest relative error of each sRGB channel (R, G, B) over the facet angles, of a table with
    band index (n_b, k_b) at ``bands`` against the plugin's render of ``spectrum`` (module docstring)."""
    grid, W = colour_weights()
    truth = _truth(spectrum) if truth is None else truth
    table = (W.T @ _hats(np.asarray(bands, float), grid).T) @ _reflectance(n_b, k_b, np.cos(np.radians(BETA_DEG)))
    # a channel the material hardly reflects (|c| < 2 % of the brightest) is measured against the brightest
    scale = np.maximum(np.abs(truth), 0.02 * np.abs(truth).max(axis=0, keepdims=True))
    return np.max(np.abs(table - truth) / scale, axis=1)


def _band_index(spectrum, bands, band_index):
    if band_index == "projected":
        return projected_index(spectrum, bands)
    return _on_grid(spectrum, np.asarray(bands, float))


@dataclass(frozen=True)
class BandChoice:
    """The bands of an export: wavelengths (nm), the index per band (paper's eta = n - jk), how the index
    was taken (``"projected"``, ``"sampled"``, or ``"given"`` for n, k given per band), whether the
    wavelengths were searched, and the colour error per sRGB channel (None: not measurable, the index
    is known at the bands only)."""

    wavelengths: tuple
    n: tuple
    k: tuple
    band_index: str
    searched: bool
    colour_error: tuple | None

    @property
    def worst(self) -> float | None:
        return None if self.colour_error is None else max(self.colour_error)

    def text(self) -> str:
        """One line for the export's summary."""
        wl = ", ".join(f"{w:d}" for w in self.wavelengths)
        how = "chosen by colour error" if self.searched else "given"
        if self.colour_error is None:
            err = "colour error not measurable (the index is known at the bands only)"
        else:
            err = ("colour error vs the Python plugin's render (D65 light): "
                   + ", ".join(f"{c} {100 * e:.2f} %" for c, e in zip(_CHANNELS, self.colour_error)))
        return f"bands {wl} nm ({how}, {self.band_index} index); {err}"


def check_wavelengths(wavelengths) -> tuple:
    """5 increasing integer wavelengths (nm) in the colour range, as a tuple; UsageError otherwise."""
    try:
        wl = tuple(int(v) for v in wavelengths)
        ok = len(wl) == MITSUBA_BANDS and all(float(a) == b for a, b in zip(wavelengths, wl))
    except (TypeError, ValueError):
        ok = False
    if not ok or not all(COLOUR_RANGE[0] <= v <= COLOUR_RANGE[1] for v in wl) or any(np.diff(wl) <= 0):
        raise UsageError(f"wavelengths must be {MITSUBA_BANDS} increasing integers (nm) in "
                         f"[{COLOUR_RANGE[0]}, {COLOUR_RANGE[1]}] (Mitsuba's measured_polarized reads exactly "
                         f"{MITSUBA_BANDS}), got {wavelengths!r}")
    return wl


def _search(spectrum, band_index, truth):
    """Coordinate descent over integer band sets (module docstring, "Choice"): (bands, error)."""
    def cost(bands):
        return float(colour_error(spectrum, bands, *_band_index(spectrum, bands, band_index), truth).max())

    best_bands, best = None, math.inf
    for start in _STARTS:
        bands, value = list(start), cost(start)
        for step in (32, 16, 8, 4, 2, 1):
            improved = True
            while improved:
                improved = False
                for i in range(MITSUBA_BANDS):
                    for d in (-step, step):
                        trial = bands.copy()
                        trial[i] += d
                        if not (COLOUR_RANGE[0] <= trial[0] and trial[-1] <= COLOUR_RANGE[1]
                                and all(np.diff(trial) > 0)):
                            continue
                        v = cost(trial)
                        if v < value - 1e-12:
                            bands, value, improved = trial, v, True
        if value < best:
            best_bands, best = bands, value
    return tuple(best_bands)


def choose_bands(spectrum, wavelengths=None, band_index="projected") -> BandChoice:
    """The bands of an export of the index ``spectrum`` (:func:`index_spectrum`): ``wavelengths`` given
    (5 integers, nm) or None (searched, module docstring), the band index per ``band_index``."""
    if band_index not in BAND_INDEX:
        raise UsageError(f"band_index must be one of {', '.join(BAND_INDEX)}, got {band_index!r}")
    truth = _truth(spectrum)
    if wavelengths is None:
        bands, searched = _search(spectrum, band_index, truth), True
    else:
        bands, searched = check_wavelengths(wavelengths), False
    n_b, k_b = _band_index(spectrum, bands, band_index)
    err = colour_error(spectrum, bands, n_b, k_b, truth)
    return BandChoice(tuple(bands), tuple(float(v) for v in n_b), tuple(float(v) for v in k_b), band_index,
                      searched, tuple(float(e) for e in err))
