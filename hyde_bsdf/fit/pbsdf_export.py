"""Export the ``hyde`` model as a ``measured_polarized`` table for Mitsuba's C++ renderer.

Python plugins are invisible to the C++ ``mitsuba`` executable and to CUDA without Python; a
table of the model in the format of Mitsuba's ``measured_polarized`` plugin
(:mod:`hyde_bsdf.io.pbsdf_file`) renders in any Mitsuba 3 build (``*_spectral_polarized``
variants).  :func:`export_pbsdf` tabulates the NumPy evaluator (:func:`hyde_bsdf.pbrdf`,
paper Eq. 17):

- grids: theta_h = (pi/2) u^2 for u uniform in [0, 1] (concentrated near 0, where the specular
  lobe is), theta_d uniform in [0, pi/2], phi_d uniform in [-pi, pi] (the paper's diffuse term
  is not reciprocal, so both signs are stored); resolution (N_pd, N_td, N_th);
- 5 bands (Mitsuba's loader reads exactly 5, interpolates linearly between them and clamps outside):
  for a Mitsuba ``data/ior`` material ("Au", ...) the band wavelengths are chosen by the colour error
  they cause and each band holds the colour-weighted projection of the index spectrum
  (:mod:`hyde_bsdf.fit.pbsdf_bands`; gold: each sRGB channel within 0.11 % of the Python plugin's
  render, 5.7 % with the index sampled at 450-650 nm), or ``wavelengths`` and ``band_index`` given;
  n, k given as scalars or 5 values (one per band, at ``wavelengths``, default 450-650 nm);
- each cell is F in the table's Stokes frames (x = normalize(omega_i x omega_r)), 1/sr;
  cells with a direction beyond the edge angle (near, at or below the horizon) are filled with
  the model at the edge (polar angles clamped to it), never NaN: Mitsuba's interpolation turns
  a NaN at any corner into a black matrix.  The edge is half a theta_d step below the horizon,
  90 deg - 45 deg / (N_td - 1) (:func:`edge_deg`): the model grows as 1/(cos theta_i cos theta_r)
  towards forward grazing specular reflection, and a node value taken closer to the horizon
  leaks into the whole last theta_d interval (measured: 37x19x19, M00 L1 error 2.5 % with the
  edge at 89 deg, 1.95 % at 87.5 deg; 13x9x11: 43 % at 89 deg, 7.6 % at 84.4 deg);
- a suggested ``alpha_sample`` (the GGX roughness Mitsuba's plugin samples with): the value
  among :data:`ALPHA_CANDIDATES` that minimizes the relative variance of f cos / pdf of
  M00 over observer angles 0-80 deg (:func:`suggest_alpha_sample`).

The interpolation error is measured on the written file (read back, interpolated as Mitsuba's
lookup does, :meth:`~hyde_bsdf.io.pbsdf_file.PbsdfTable.interpolate`) against the exact model
at random geometries (cosine-distributed light directions, observers half cosine-distributed
and half from the Beckmann lobe; seeded): the relative L1 error of M00 weighted by
cos theta_i cos theta_r, and the energy-weighted median and 95th percentile of the largest
normalized-element error max_jk |M_jk/M00 - F_jk/F00| in the paper's bases
(:func:`interpolation_error`).  The file stores these, the parameters and the suggested
``alpha_sample`` in an extra field ``hyde_export`` (JSON) that Mitsuba ignores.

Reliability: the table size is checked before any work against Mitsuba's 32-bit indices
(< 2^32 floats), the free disk space of the target folder and the available memory (Mitsuba's
loader holds the mapped file and a copy of it: 2x the file size); ``M`` is streamed slab by
slab (one phi_d slice in memory) into a temporary file renamed at the end (atomic).

The command line (``hyde-bsdf export``) is :mod:`hyde_bsdf.app.export`.
"""
from __future__ import annotations

import json
import math
import os
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from hyde_bsdf.io.atomic import atomic_path
from hyde_bsdf.errors import UsageError, shorten
from hyde_bsdf.fit.pbsdf_bands import COLOUR_TARGET, BandChoice, check_wavelengths, choose_bands, index_spectrum
from hyde_bsdf.fit.pbsdf_samples import paper_angles, paper_to_table, table_to_paper
from hyde_bsdf.io.ior import material_files
from hyde_bsdf.io.output_gate import check_free_space, check_output_path
from hyde_bsdf.io.pbsdf_file import (KAIST_WAVELENGTHS, PbsdfTable, read_pbsdf, rusinkiewicz_to_directions,
                                     table_frame_x, table_nbytes, write_table)
from hyde_bsdf.model.evaluator import pbrdf
from hyde_bsdf.model.index import Index
from hyde_bsdf.model.parameters import ALPHA_SAMPLE, DIFFUSE_REFLECTANCE, INDEX_MIN, N, RMS_SLOPE
from hyde_bsdf.model.terms import RENDER_DEFAULT, check_pair, term_arguments
from hyde_bsdf.options import Options
from hyde_bsdf.progress import PROGRESS_SECONDS, Throttle, as_callback
from hyde_bsdf.resources import COSTS, OutputLock, check_memory, format_bytes

__all__ = ["DEFAULT_RESOLUTION", "edge_deg", "ALPHA_CANDIDATES", "ExportReport", "grids",
           "band_index", "check_table_size", "interpolation_error", "suggest_alpha_sample",
           "ExportOptions", "export_pbsdf"]

#: (N_phi_d, N_theta_d, N_theta_h) of the default export: the smallest table of the sweep in
#: hyde_bsdf/validation/pbsdf_export.py with an M00 L1 error <= 1 % and normalized elements within 2 % (95th
#: percentile) for gold at rms_slope 0.3 and 0.1 (35 MB; phi_d resolution hardly matters: the table's
#: frames follow the facet, so 37, 73 and 145 phi_d nodes give the same error)
DEFAULT_RESOLUTION = (37, 55, 55)
#: GGX alphas tried for the suggested ``alpha_sample``
ALPHA_CANDIDATES = tuple(float(a) for a in np.round(np.geomspace(0.005, 1.0, 24), 4))
#: Mitsuba's Marginal2D indexes the table with 32-bit integers
MAX_ELEMENTS = 2 ** 32 - 1
_JSON_BYTES = 4096
RESOLUTION_RANGE = (2, 4097)


def grids(resolution=DEFAULT_RESOLUTION):
    """(phi_d, theta_d, theta_h) grids in radians (float64) of an export of this resolution."""
    n_pd, n_td, n_th = _check_resolution(resolution)
    u = np.linspace(0.0, 1.0, n_th)
    return (np.linspace(-math.pi, math.pi, n_pd), np.linspace(0.0, math.pi / 2, n_td),
            (math.pi / 2) * u * u)


def _check_resolution(resolution):
    if isinstance(resolution, str):
        try:
            resolution = tuple(int(v) for v in resolution.lower().split("x"))
        except ValueError:
            raise UsageError(f"resolution must look like 37x55x55 (N_phi_d x N_theta_d x N_theta_h), "
                             f"got {resolution!r}") from None
    try:
        res = tuple(int(v) for v in resolution)
        ok = len(res) == 3 and all(float(v) == int(v) for v in resolution)
    except (TypeError, ValueError):
        ok = False
    if not ok or not all(RESOLUTION_RANGE[0] <= v <= RESOLUTION_RANGE[1] for v in res):
        raise UsageError(f"resolution must be 3 integers (N_phi_d, N_theta_d, N_theta_h), each in "
                         f"[{RESOLUTION_RANGE[0]}, {RESOLUTION_RANGE[1]}], got {resolution!r}")
    return res


# ---------------------------------------------------------------------------------------------
# the index per band

def _read_spd(path: Path):
    data = np.loadtxt(path, comments="#")
    return data[:, 0], data[:, 1]


def band_index(wavelengths=KAIST_WAVELENGTHS, n=None, k=None, material=None):
    """(n, k) arrays, one value per band: scalars broadcast, sequences of one value per band, or a
    Mitsuba ``data/ior`` material ("Au", "Cu", ...) interpolated linearly at the band centres
    (as Mitsuba's spectra are).  eta = n - jk in the paper's sign (the plugin's eta = n, k = k)."""
    wl = np.asarray(wavelengths, float)
    if material is not None:
        if n is not None or k is not None:
            raise UsageError("give either material or n and k, not both")
        out = []
        for spd in material_files(material):          # data/ior names only (no ../)
            x, y = _read_spd(spd)
            out.append(np.interp(wl, x, y))
        return out[0], out[1]
    if n is None:
        raise UsageError("give the index: n (and k), or material (e.g. 'Au')")
    vals = []
    for name, v in (("n", n), ("k", 0.0 if k is None else k)):
        a = np.atleast_1d(np.asarray(v, dtype=float))
        if a.ndim != 1 or a.size not in (1, wl.size):
            raise UsageError(f"{name} must be one value or {wl.size} (one per band {wl.tolist()} nm), got {v!r}")
        if not np.all(np.isfinite(a)) or np.any(a < N.lo) or np.any(a > N.hi):
            raise UsageError(f"{name} must be finite and in {N.text()}, got {v!r}")
        vals.append(np.broadcast_to(a, wl.shape).astype(float))
    if np.any(np.hypot(*vals) < INDEX_MIN):
        raise UsageError(f"n and k cannot both be 0 (|eta| >= {INDEX_MIN:g}) in any band")
    return vals[0], vals[1]


# ---------------------------------------------------------------------------------------------
# size checks

def check_table_size(path, resolution, bands: int = len(KAIST_WAVELENGTHS)) -> int:
    """Refuse (UsageError, before any work) a table that Mitsuba cannot index (>= 2^32 floats), that
    does not fit on the disk of ``path``'s folder, or whose loading (about 2x the file size: the
    mapped file and the loader's copy, :data:`~hyde_bsdf.resources.COSTS`) exceeds the available memory.
    Returns the file size in bytes."""
    n_pd, n_td, n_th = _check_resolution(resolution)
    elements = n_pd * n_td * n_th * bands * 16
    nbytes = table_nbytes(n_pd, n_td, n_th, bands) + _JSON_BYTES
    res = f"{n_pd}x{n_td}x{n_th}"
    if elements > MAX_ELEMENTS:
        raise UsageError(f"resolution {res}: {elements} table values exceed Mitsuba's 32-bit index "
                         f"limit ({MAX_ELEMENTS}); choose a smaller resolution")
    folder = Path(path).parent if str(Path(path).parent) else Path(".")
    check_free_space(folder, nbytes, f"pBSDF file {shorten(str(path))} (resolution {res})",
                     "choose a smaller resolution or another folder")
    check_memory(COSTS.pbsdf_loader_copies * nbytes, f"loading the {res} table ({format_bytes(nbytes)}) in "
                 "Mitsuba", "choose a smaller resolution")
    return nbytes


# ---------------------------------------------------------------------------------------------
# tabulation

def edge_deg(n_theta_d: int) -> float:
    """The polar angle (degrees) at which an export of N_td theta_d nodes clamps its directions:
    half a theta_d step below the horizon."""
    return 90.0 - 45.0 / (n_theta_d - 1)


def _edge_directions(om_i, om_r, x_fallback, edge):
    """Directions with polar angles clamped to ``edge`` degrees (cells at, near or below the
    horizon), and the table frame's x axis (``x_fallback`` where omega_i = omega_r)."""
    cmax = math.cos(math.radians(edge))
    out = []
    for om in (om_i, om_r):
        z = om[..., 2]
        clamp = z < cmax
        horiz = np.hypot(om[..., 0], om[..., 1])
        scale = np.where(horiz > 0, math.sqrt(1 - cmax * cmax) / np.where(horiz > 0, horiz, 1.0), 1.0)
        new = om.copy()
        new[..., 0] = np.where(clamp, om[..., 0] * scale, om[..., 0])
        new[..., 1] = np.where(clamp, om[..., 1] * scale, om[..., 1])
        new[..., 2] = np.where(clamp, cmax, z)
        out.append(new)
    x = table_frame_x(*out)
    bad = ~np.isfinite(x).all(-1) | (np.linalg.norm(np.cross(out[0], out[1]), axis=-1) < 1e-9)
    x = np.where(bad[..., None], x_fallback, x)
    return out[0], out[1], x


def band_indices(params) -> list:
    """The :class:`~hyde_bsdf.model.index.Index` of each band of an export's parameters."""
    return [Index(n, k) for n, k in zip(params["n"], params["k"])]


def _model(theta_i, theta_r, phi, params, band):
    albedo = params.get("diffuse_reflectance")
    return pbrdf(theta_i, theta_r, phi, rms_slope=params["rms_slope"], index=band_indices(params)[band],
                 shadowing=params["shadowing"], diffuse=params["diffuse"],
                 diffuse_reflectance=None if albedo is None else albedo[band])


def _slab(p, phi_d, theta_d, theta_h, params):
    """M for one phi_d node: (N_td, N_th, K, 4, 4) float32, table frames."""
    om_i, om_r, x = rusinkiewicz_to_directions(phi_d[p], theta_d[:, None], theta_h[None, :])
    oi, orr, x = _edge_directions(om_i, om_r, x, edge_deg(theta_d.size))
    ti, tr, ph, _, _ = paper_angles(oi, orr)
    K = len(params["n"])
    out = np.empty(ti.shape + (K, 4, 4), np.float32)
    for b in range(K):
        F = _model(ti, tr, ph, params, b)
        out[..., b, :, :] = paper_to_table(F, oi, orr, x)
    return out


# ---------------------------------------------------------------------------------------------
# error and sampling measures

def _query_geometries(count, rms_slope, rng):
    """(omega_i, omega_r, weight): light cosine-distributed; observers half cosine-distributed and
    half mirrored about Beckmann normals; weight = cos theta_r / (mixture pdf of omega_r)
    (the light's cos / pdf = pi is common to all and drops out of every ratio)."""
    def cosine(m):
        u1, u2 = rng.random(m), rng.random(m)
        r, ph = np.sqrt(u1), 2 * math.pi * u2
        return np.stack([r * np.cos(ph), r * np.sin(ph), np.sqrt(np.maximum(1 - u1, 0))], -1)

    alpha = math.sqrt(2.0) * rms_slope
    om_i = cosine(count)
    half = count // 2
    om_r = np.empty_like(om_i)
    om_r[:half] = cosine(half)
    t2 = -alpha * alpha * np.log1p(-rng.random(count - half))
    ph = 2 * math.pi * rng.random(count - half)
    ct = 1 / np.sqrt(1 + t2)
    st = np.sqrt(np.maximum(1 - ct * ct, 0))
    h = np.stack([st * np.cos(ph), st * np.sin(ph), ct], -1)
    oi = om_i[half:]
    om_r[half:] = 2 * np.sum(oi * h, -1, keepdims=True) * h - oi
    # mixture pdf of omega_r given omega_i
    hr = om_i + om_r
    hr /= np.linalg.norm(hr, axis=-1, keepdims=True)
    c = np.clip(hr[..., 2], 1e-12, 1.0)
    tan2 = (1 - c * c) / (c * c)
    D = np.exp(-tan2 / (alpha * alpha)) / (math.pi * alpha * alpha * c ** 4)
    with np.errstate(divide="ignore", invalid="ignore"):
        p_lobe = D * c / (4 * np.abs(np.sum(om_r * hr, -1)))
    cr = om_r[..., 2]
    pdf = 0.5 * np.maximum(cr, 0) / math.pi + 0.5 * np.where(hr[..., 2] > 0, p_lobe, 0.0)
    up = (cr > 1e-6) & (om_i[..., 2] > 1e-6) & np.isfinite(pdf) & (pdf > 0)
    weight = np.where(up, np.maximum(cr, 0) / np.where(up, pdf, 1.0), 0.0)
    return om_i[up], om_r[up], weight[up]


def _weighted_quantile(values, weights, q):
    order = np.argsort(values)
    v, w = values[order], weights[order]
    cum = np.cumsum(w)
    if cum[-1] <= 0:
        return float("nan")
    return float(v[min(np.searchsorted(cum, q * cum[-1]), v.size - 1)])


def error_statistics(F_test, F_true, weight) -> dict:
    """The export's error measures of matrices F_test against F_true (both (N, 4, 4), the paper's
    bases) at geometries of the given weights (cos theta_r / pdf): ``m00_l1`` = sum w |dF00| /
    sum w F00; ``m00_p95`` the F00-energy-weighted 95th percentile of |dF00| / F00; ``pol_median``,
    ``pol_p95`` the same quantiles of max_jk |F_jk/F00 - G_jk/G00| (the 15 normalized elements)."""
    t00, m00 = F_test[:, 0, 0], F_true[:, 0, 0]
    ok = m00 > 0
    energy = weight * np.where(ok, m00, 0.0)
    l1 = float(np.sum(weight * np.abs(t00 - m00)) / max(np.sum(energy), 1e-300))
    with np.errstate(divide="ignore", invalid="ignore"):
        rel = np.where(ok, np.abs(t00 - m00) / m00, 0.0)
        nt = F_test / np.where(t00 > 0, t00, np.inf)[:, None, None]
        nm = F_true / np.where(ok, m00, np.inf)[:, None, None]
    diff = np.abs(nt - nm).reshape(-1, 16)[:, 1:].max(-1)
    diff = np.where(t00 > 0, diff, 1.0)            # a black table cell has lost all polarization
    return {"m00_l1": l1, "m00_p95": _weighted_quantile(rel, energy, 0.95),
            "pol_median": _weighted_quantile(diff, energy, 0.5),
            "pol_p95": _weighted_quantile(diff, energy, 0.95)}


def interpolation_error(table: PbsdfTable, params: dict, samples: int = 20000, seed: int = 0) -> dict:
    """The table's interpolation error against the model (see the module docstring) for each band
    at its centre wavelength, and the worst band.  ``params``: rms_slope, n, k (per band),
    shadowing, diffuse.  Returns {"by_band": {nm: stats}, worst stats..., "samples": count}."""
    rng = np.random.default_rng(seed)
    om_i, om_r, w = _query_geometries(samples, params["rms_slope"], rng)
    ti, tr, ph, _, _ = paper_angles(om_i, om_r)
    by_band = {}
    for b, wl in enumerate(table.wavelengths):
        T = table_to_paper(table.interpolate_directions(om_i, om_r, wl), om_i, om_r)
        by_band[int(wl)] = error_statistics(T, _model(ti, tr, ph, params, b), w)
    worst = {key: max(s[key] for s in by_band.values()) for key in next(iter(by_band.values()))}
    return {**worst, "by_band": by_band, "samples": int(w.size)}


def _ggx_pdf(wi, wo, alpha):
    """Mitsuba's ``measured_polarized`` sampling density of wo given wi (10 % cosine, 90 % GGX
    visible normals with ``alpha_sample``), float64 NumPy."""
    H = wi + wo
    H /= np.linalg.norm(H, axis=-1, keepdims=True)
    c = np.clip(H[..., 2], 1e-12, 1.0)
    t2 = (1 - c * c) / (c * c)
    a2 = alpha * alpha
    D = 1.0 / (math.pi * a2 * c ** 4 * (1 + t2 / a2) ** 2)
    ci = np.clip(wi[..., 2], 1e-12, 1.0)
    t2i = (1 - ci * ci) / (ci * ci)
    G1 = 2.0 / (1.0 + np.sqrt(1.0 + a2 * t2i))
    wim = np.sum(wi * H, -1)
    G1 = np.where(wim / ci > 0, G1, 0.0)
    with np.errstate(divide="ignore", invalid="ignore"):
        pm = D * G1 * np.maximum(wim, 0) / ci / (4 * np.sum(wo * H, -1))
    pm = np.where(np.isfinite(pm) & (H[..., 2] > 0), pm, 0.0)
    return 0.1 * np.maximum(wo[..., 2], 0) / math.pi + 0.9 * pm


def suggest_alpha_sample(params: dict, band: int | None = None, view_deg=(0, 20, 40, 60, 80),
                         n_theta: int = 160, n_phi: int = 160) -> tuple[float, dict]:
    """The ``alpha_sample`` of :data:`ALPHA_CANDIDATES` with the least mean relative variance of
    Mitsuba's sampling weight f cos / pdf (M00 of the middle band) over the observer angles
    ``view_deg``, by quadrature on a (theta, phi) grid of the light direction.  Returns
    (alpha, {alpha: relative variance})."""
    band = len(params["n"]) // 2 if band is None else band
    t_edges = np.linspace(0, math.pi / 2, n_theta + 1)
    tc = 0.5 * (t_edges[1:] + t_edges[:-1])
    pc = (np.arange(n_phi) + 0.5) * 2 * math.pi / n_phi
    T, P = np.meshgrid(tc, pc, indexing="ij")
    dw = (np.cos(t_edges[:-1]) - np.cos(t_edges[1:]))[:, None] * (2 * math.pi / n_phi)
    wo = np.stack([np.sin(T) * np.cos(P), np.sin(T) * np.sin(P), np.cos(T)], -1)
    score = {a: 0.0 for a in ALPHA_CANDIDATES}
    for vd in view_deg:
        v = math.radians(vd)
        wi = np.broadcast_to(np.array([math.sin(v), 0.0, math.cos(v)]), wo.shape)
        g = _model(T, v, np.mod(-P, 2 * math.pi), params, band)[..., 0, 0] * np.cos(T)
        integral = float(np.sum(g * dw))
        if integral <= 0:
            continue
        for a in ALPHA_CANDIDATES:
            p = _ggx_pdf(wi, wo, a)
            with np.errstate(divide="ignore", invalid="ignore"):
                m2 = float(np.sum(np.where(g > 0, g * g / p, 0.0) * dw))
            score[a] += (m2 / integral ** 2 - 1.0) / len(view_deg)
    best = min(score, key=lambda a: (score[a] if math.isfinite(score[a]) else math.inf))
    return best, score


# ---------------------------------------------------------------------------------------------
# the export

@dataclass
class ExportReport:
    """What :func:`export_pbsdf` wrote and measured."""

    path: Path
    resolution: tuple
    nbytes: int
    seconds: float
    params: dict
    wavelengths: tuple
    alpha_sample: float
    errors: dict = field(default_factory=dict)
    bands: BandChoice | None = None

    def xml(self, indent: str = "") -> str:
        """The ``<bsdf type="measured_polarized">`` element that loads the file."""
        from xml.sax.saxutils import quoteattr

        return (f'{indent}<bsdf type="measured_polarized">\n'
                f'{indent}    <string name="filename" value={quoteattr(self.path.name)}/>\n'
                f'{indent}    <float name="alpha_sample" value="{self.alpha_sample:.4g}"/>\n'
                f'{indent}</bsdf>')

    def summary(self) -> str:
        p = self.params
        idx = ", ".join(f"{w:g} nm: {i.n:.4g} - j{i.k:.4g}" for w, i in zip(self.wavelengths, band_indices(p)))
        lines = [f"wrote {self.path} ({self.nbytes / 2**20:.1f} MiB, {'x'.join(map(str, self.resolution))} "
                 f"phi_d x theta_d x theta_h x {len(self.wavelengths)} bands, {self.seconds:.1f} s)",
                 f"  hyde: rms_slope = {p['rms_slope']:.6g}, shadowing = {p['shadowing']}, diffuse = {p['diffuse']}"
                 + (f", diffuse_reflectance = {', '.join(f'{a:.4g}' for a in p['diffuse_reflectance'])}"
                    if p.get("diffuse_reflectance") else ""),
                 f"  index (paper eta = n - jk): {idx}"]
        if self.bands is not None:
            lines.append(f"  {self.bands.text()}")
            if self.bands.worst is not None and self.bands.worst > COLOUR_TARGET:
                lines.append(f"  WARNING: a colour channel is off by more than {100 * COLOUR_TARGET:g} %: see "
                             f"docs/tutorials/pbsdf.md (materials whose table ends inside 360-830 nm or has gaps)")
        e = self.errors
        if e:
            lines.append(f"  interpolation error (worst band, {e['samples']} geometries): M00 L1 "
                         f"{100 * e['m00_l1']:.2f} %, M00 p95 {100 * e['m00_p95']:.2f} %; normalized elements "
                         f"median {100 * e['pol_median']:.3f} %, p95 {100 * e['pol_p95']:.2f} %")
        lines.append(f"  suggested alpha_sample = {self.alpha_sample:.4g}")
        return "\n".join(lines)


def _bands(n, k, material, bands) -> BandChoice:
    """The export's bands (:mod:`hyde_bsdf.fit.pbsdf_bands`): ``bands`` a BandChoice is used as it is
    (``material`` then only names it);
    otherwise (None or 5 wavelengths) for a material the wavelengths are chosen by colour error (unless
    given) and each band holds the projected index; n, k given per band or as constants are at the
    given wavelengths (default 450-650 nm)."""
    if isinstance(bands, BandChoice):
        if n is not None or k is not None:
            raise UsageError("bands (a BandChoice) holds the index: do not also give n and k")
        return bands
    if material is not None:
        if n is not None or k is not None:
            raise UsageError("give either material or n and k, not both")
        return choose_bands(index_spectrum(material), bands)
    bands = check_wavelengths(KAIST_WAVELENGTHS if bands is None else bands)
    nb, kb = band_index(bands, n, k)
    constant = np.ptp(nb) == 0 and np.ptp(kb) == 0       # no spectrum, no colour error
    return BandChoice(bands, tuple(float(v) for v in nb), tuple(float(v) for v in kb), "given", False,
                      (0.0, 0.0, 0.0) if constant else None)


def _check_params(rms_slope, n, k, material, shadowing, diffuse, bands=None, diffuse_reflectance=None):
    if not isinstance(rms_slope, (int, float)) or isinstance(rms_slope, bool) or not RMS_SLOPE.contains(rms_slope):
        raise UsageError(f"rms_slope must be a number in [{RMS_SLOPE.lo:g}, {RMS_SLOPE.hi:g}], got {rms_slope!r}")
    term = check_pair(shadowing, diffuse, booleans=False)[1]     # names only: the export takes no True/False
    params = {"shadowing": shadowing, "diffuse": diffuse}
    if "diffuse_reflectance" not in term.parameters:
        term_arguments(term, diffuse_reflectance=diffuse_reflectance)     # refuses an albedo, naming its term
    elif diffuse_reflectance is None:      # no silent default: a table is a material, its albedo is measured
        raise UsageError(f"diffuse_reflectance must be given with diffuse={diffuse!r}: the Lambertian term's own "
                         "albedo, one value or one per band (a fit's is in the JSON the fit command writes)")
    else:
        a = np.atleast_1d(np.asarray(diffuse_reflectance, float))
        if a.ndim != 1 or a.size not in (1, len(KAIST_WAVELENGTHS)):
            raise UsageError(f"diffuse_reflectance must be one value or {len(KAIST_WAVELENGTHS)} (one per band), "
                             f"got {diffuse_reflectance!r}")
        params["diffuse_reflectance"] = [DIFFUSE_REFLECTANCE.check(float(x), "diffuse_reflectance")
                                         for x in np.broadcast_to(a, (len(KAIST_WAVELENGTHS),))]
    bands = _bands(n, k, material, bands)
    return {"rms_slope": float(rms_slope), "n": list(bands.n), "k": list(bands.k), "material": material,
            **params}, bands


@dataclass(frozen=True)
class ExportOptions(Options):
    """The table's size and the export's reporting (each field is also a keyword of :func:`export_pbsdf`;
    its docstring describes them)."""

    resolution: object = DEFAULT_RESOLUTION
    error_samples: int = 20000
    alpha_sample: float | None = None
    seed: int = 0
    progress: object = None


def export_pbsdf(path, *, rms_slope, n=None, k=None, material=None, shadowing=RENDER_DEFAULT[0],
                 diffuse=RENDER_DEFAULT[1], diffuse_reflectance=None, bands=None,
                 options: ExportOptions | None = None, **settings) -> ExportReport:
    """Write the ``hyde`` model as a ``measured_polarized`` table (see the module docstring).

    The table's size and the reporting are an :class:`ExportOptions` (``options``), or its fields given as
    keywords: ``resolution``, ``error_samples``, ``alpha_sample``, ``seed``, ``progress`` below.

    Parameters: ``rms_slope`` (the paper's), the index as ``n``/``k`` (eta = n - jk; one value or
    one per band) or ``material`` (Mitsuba ``data/ior`` name), ``shadowing``, ``diffuse`` (as
    :func:`hyde_bsdf.pbrdf`; default the renderers' material, ``terms.RENDER_DEFAULT``: the plugin's
    default, which conserves energy in a path tracer), ``resolution`` (N_phi_d, N_theta_d, N_theta_h) or "37x55x55",
    ``error_samples`` geometries for the error estimate (0: skip it), ``alpha_sample`` (default:
    :func:`suggest_alpha_sample`), ``seed`` of the error geometries, ``progress`` a callback
    ``progress(message)`` (True: lines on stderr; :mod:`hyde_bsdf.progress`), ``bands`` the five
    band wavelengths (nm; default: chosen by colour error for a material, 450-650 nm for n, k) or a
    :class:`~hyde_bsdf.fit.pbsdf_bands.BandChoice` (e.g. ``choose_bands(index_spectrum("Au"),
    (450, 500, 550, 600, 650), "sampled")``, the index sampled at the band wavelengths),
    ``diffuse_reflectance`` the albedo of ``diffuse="lambertian"`` (one value or one per band; required
    with it).
    Everything is checked, and the size refused (:func:`check_table_size`), before any work.
    """
    t0 = time.perf_counter()
    o = ExportOptions.of(options, settings, "export_pbsdf")
    resolution, error_samples, alpha_sample, seed, progress = (o.resolution, o.error_samples, o.alpha_sample, o.seed,
                                                               o.progress)
    params, choice = _check_params(rms_slope, n, k, material, shadowing, diffuse, bands, diffuse_reflectance)
    wavelengths = choice.wavelengths
    res = _check_resolution(resolution)
    if not (isinstance(error_samples, (int, np.integer)) and 0 <= error_samples <= 10**7):
        raise UsageError(f"error_samples must be an integer in [0, 1e7], got {error_samples!r}")
    if alpha_sample is not None and not (isinstance(alpha_sample, (int, float)) and ALPHA_SAMPLE.contains(alpha_sample)):
        raise UsageError(f"alpha_sample must be in {ALPHA_SAMPLE.text()}, got {alpha_sample!r}")
    path = check_output_path(path, "pBSDF file")
    check_table_size(path, res, len(wavelengths))
    pd, td, th = grids(res)
    callback = as_callback(progress)
    say = (lambda text: callback(f"export: {text}")) if callback else (lambda text: None)
    report = Throttle(say, PROGRESS_SECONDS)

    def slabs():
        for p in range(res[0]):
            yield _slab(p, pd, td, th, params)
            report(lambda: f"tabulating phi_d {p + 1}/{res[0]} ({100 * (p + 1) / res[0]:.0f} %), "
                           f"{time.perf_counter() - t0:.0f} s")

    with OutputLock([path], "pBSDF file"), atomic_path(path) as tmp:     # one writer at a time
        meta = {"producer": "hyde-bsdf export", "model": "Hyde, Schmidt, Havrilla, Opt. Express 17(24) 2009, Eq. 17",
                **params, "resolution": list(res), "wavelengths_nm": list(wavelengths),
                "bands": {"band_index": choice.band_index, "chosen_by_colour_error": choice.searched,
                          "colour_error_rgb": choice.colour_error},
                "theta_h_grid": "(pi/2) u^2", "edge_deg": edge_deg(res[1])}
        offsets = write_table(tmp, th, td, pd, wavelengths, slabs(), extra={"hyde_export": " " * _JSON_BYTES})
        table = read_pbsdf(tmp)
        errors = {}
        if error_samples:
            say(f"measuring the interpolation error at {error_samples} geometries")
            errors = interpolation_error(table, params, error_samples, seed)
        if alpha_sample is None:
            say("choosing alpha_sample")
            alpha_sample, _ = suggest_alpha_sample(params)
        del table
        _write_metadata(tmp, offsets["hyde_export"], meta, errors, alpha_sample)
    return ExportReport(path=Path(path), resolution=res, nbytes=os.path.getsize(path),
                        seconds=time.perf_counter() - t0, params=params, wavelengths=tuple(wavelengths),
                        alpha_sample=float(alpha_sample), errors=errors, bands=choice)


def _write_metadata(tmp, offset, meta, errors, alpha_sample):
    """The JSON metadata (with the measured errors and alpha_sample) into its fixed-size field;
    the per-band errors are dropped when they do not fit."""
    meta.update(errors={k_: v for k_, v in errors.items()}, alpha_sample=float(alpha_sample))
    text = json.dumps(meta, separators=(",", ":"))
    if len(text.encode()) > _JSON_BYTES:
        meta["errors"] = {k_: v for k_, v in errors.items() if k_ != "by_band"}
        text = json.dumps(meta, separators=(",", ":"))
    with open(tmp, "r+b") as f:
        f.seek(offset)
        f.write(text.encode().ljust(_JSON_BYTES, b" "))
