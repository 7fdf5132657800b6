"""A measured pBRDF table in the paper's terms: frames, cell classification, samples for fitting.

The table (:mod:`hyde_bsdf.io.pbsdf_file`, Mitsuba's ``measured_polarized`` format) stores Mueller
matrices in frames whose x axis is normalize(omega_i x omega_r); :func:`table_to_paper` and
:func:`paper_to_table` rotate them to and from the paper's s/p bases (S3 has the same sign in both).

Reading for fitting (:func:`pbsdf_samples`): cells are classified below-horizon (either direction
at or below the surface: Mitsuba never evaluates there), non-finite (NaN or inf in any element:
KAIST raw files have many) and non-physical (M00 <= 0, or |M_jk| > (1 + tol) M00, or a
diattenuation / polarizance vector longer than (1 + tol) M00); the counts are reported
(:class:`CellCounts`).  The usable cells are converted to the paper's angles (theta_i, theta_r,
phi = phi_r - phi_i; phi = pi the specular plane) and Stokes bases
(:mod:`hyde_bsdf.model.evaluator`) and subsampled (fixed seed) for fitting.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from hyde_bsdf.errors import UsageError
from hyde_bsdf.io.pbsdf_file import PbsdfFileError, PbsdfTable, read_pbsdf, table_frame_x
from hyde_bsdf.progress import Throttle, as_callback

__all__ = ["CellCounts", "PbsdfSamples", "paper_angles", "table_to_paper", "paper_to_table",
           "classify_cells", "pbsdf_samples"]


def paper_angles(om_i, om_r):
    """(theta_i, theta_r, phi, phi_i, phi_r) of directions to the light and observer (radians;
    phi = phi_r - phi_i in [0, 2 pi), the paper's angles; azimuth 0 at the pole)."""
    om_i = np.asarray(om_i, float)
    om_r = np.asarray(om_r, float)
    ti = np.arccos(np.clip(om_i[..., 2], -1, 1))
    tr = np.arccos(np.clip(om_r[..., 2], -1, 1))
    pi_ = np.arctan2(om_i[..., 1], om_i[..., 0])
    pr = np.arctan2(om_r[..., 1], om_r[..., 0])
    return ti, tr, np.mod(pr - pi_, 2 * np.pi), pi_, pr


def _angle(x_from, x_to, k):
    """Angle from basis vector x_from to x_to, counter-clockwise about the propagation k."""
    return np.arctan2(np.sum(np.cross(x_from, x_to) * k, -1), np.sum(x_from * x_to, -1))


def _rotator(angle):
    """Stokes rotation R (..., 4, 4): S in the basis x_b = cos a x_a + sin a y_a is R S_a."""
    c, s = np.cos(2 * angle), np.sin(2 * angle)
    R = np.zeros(np.shape(angle) + (4, 4))
    R[..., 0, 0] = R[..., 3, 3] = 1.0
    R[..., 1, 1] = R[..., 2, 2] = c
    R[..., 1, 2] = s
    R[..., 2, 1] = -s
    return R


def _paper_axes(phi_i, phi_r):
    """The paper's s axes of the incident and reflected waves (limit at fixed azimuth at theta = 0)."""
    s_i = np.stack([-np.sin(phi_i), np.cos(phi_i), np.zeros_like(phi_i)], -1)
    s_r = np.stack([np.sin(phi_r), -np.cos(phi_r), np.zeros_like(phi_r)], -1)
    return s_i, s_r


def _rotations(om_i, om_r, x_table):
    """(angle in: paper s_i -> table x about k_i = -omega_i, angle out: table x -> paper s_r about omega_r)."""
    _, _, _, pi_, pr = paper_angles(om_i, om_r)
    s_i, s_r = _paper_axes(pi_, pr)
    return _angle(s_i, x_table, -om_i), _angle(x_table, s_r, om_r)


def table_to_paper(M, om_i, om_r, x_table=None):
    """Mueller matrices (..., 4, 4) in the table's frames -> the paper's s/p bases.

    ``om_i``, ``om_r``: directions to the light and the observer (..., 3); ``x_table`` the table
    frame's x axis (default normalize(om_i x om_r); give it where om_i = om_r).
    """
    x = table_frame_x(om_i, om_r) if x_table is None else x_table
    a_in, a_out = _rotations(om_i, om_r, x)
    return _rotator(a_out) @ M @ _rotator(a_in)


def paper_to_table(F, om_i, om_r, x_table=None):
    """The inverse of :func:`table_to_paper`: the paper's bases -> the table's frames."""
    x = table_frame_x(om_i, om_r) if x_table is None else x_table
    a_in, a_out = _rotations(om_i, om_r, x)
    return _rotator(-a_out) @ F @ _rotator(-a_in)


@dataclass
class CellCounts:
    """How many cells (geometry x band) a table has, and why some cannot be used."""

    total: int
    below_horizon: int
    nonfinite: int
    nonphysical: int
    usable: int
    #: per reason of non-physicality: name -> count
    detail: dict = field(default_factory=dict)

    def summary(self) -> str:
        pct = lambda n: f"{100.0 * n / max(self.total, 1):.1f} %"
        extra = "".join(f"; {k} {v}" for k, v in self.detail.items() if v)
        return (f"{self.total} cells (geometry x band): {self.usable} usable ({pct(self.usable)}), "
                f"{self.below_horizon} below the horizon, {self.nonfinite} with NaN/inf, "
                f"{self.nonphysical} non-physical{extra}")


def classify_cells(M, up, tolerance: float = 0.05):
    """Masks of one slab of cells: (usable, nonfinite, nonphysical, detail counts).

    ``M`` (..., K, 4, 4); ``up`` (...) True where both directions are above the horizon.
    Non-physical: M00 <= 0, or |M_jk| > (1 + tolerance) M00, or |(M01, M02, M03)| or
    |(M10, M20, M30)| > (1 + tolerance) M00 (a degree of polarization above 1).
    """
    M = np.asarray(M, float)
    up = np.broadcast_to(np.asarray(up, bool)[..., None], M.shape[:-2])
    finite = np.isfinite(M).all(axis=(-2, -1))
    with np.errstate(invalid="ignore"):
        m00 = M[..., 0, 0]
        lim = (1.0 + tolerance) * m00
        nonpos = finite & (m00 <= 0)
        elem = finite & ~nonpos & (np.abs(M).max(axis=(-2, -1)) > lim)
        diat = finite & ~nonpos & (np.linalg.norm(M[..., 0, 1:], axis=-1) > lim)
        polz = finite & ~nonpos & (np.linalg.norm(M[..., 1:, 0], axis=-1) > lim)
    nonphys = nonpos | elem | diat | polz
    usable = up & finite & ~nonphys
    detail = {"M00 <= 0": int((up & nonpos).sum()), "|M_jk| > M00": int((up & elem).sum()),
              "diattenuation > 1": int((up & diat).sum()), "polarizance > 1": int((up & polz).sum())}
    return usable, up & ~finite, up & finite & nonphys, detail


@dataclass
class PbsdfSamples:
    """Usable cells of a table in the paper's angles and Stokes bases, for fitting.

    ``theta_i``, ``theta_r``, ``phi`` (N,) radians; ``F`` (K, N, 4, 4) the Mueller BRDF (1/sr)
    in the paper's bases; ``wavelengths`` (K,) nm; ``counts`` the cell classification of the
    whole table; ``cells`` (N, 3) the (phi_d, theta_d, theta_h) indices of each sample.
    A geometry is kept when it is usable in every band.
    """

    theta_i: np.ndarray
    theta_r: np.ndarray
    phi: np.ndarray
    F: np.ndarray
    wavelengths: np.ndarray
    counts: CellCounts
    cells: np.ndarray
    source: str = "<memory>"
    usable_geometries: int = 0

    def __len__(self) -> int:
        return int(self.theta_i.size)

    def normalized(self):
        """F / F00, (K, N, 4, 4)."""
        return self.F / self.F[..., :1, :1]

    def measurements(self, band: int):
        """One band as :class:`hyde_bsdf.io.measurements.Measurements` (the 15 normalized
        elements, no sigma) for :func:`hyde_bsdf.fit.fit_measurements`."""
        from hyde_bsdf.io.measurements import ELEMENT_NAMES, Measurements

        N = self.normalized()[band]
        values = {n: N[:, int(n[1]), int(n[2])].copy() for n in ELEMENT_NAMES}
        return Measurements(self.theta_i.copy(), self.theta_r.copy(), self.phi.copy(), values,
                            source=f"{self.source} @ {self.wavelengths[band]:g} nm")


def pbsdf_samples(table, max_points: int = 3000, theta_max: float = math.radians(80.0),
                  tolerance: float = 0.05, seed: int = 0, progress=None) -> PbsdfSamples:
    """Mask, convert and subsample a table (a :class:`PbsdfTable` or a path) for fitting.

    Cells are classified (:func:`classify_cells`; counts for the whole table, every band);
    geometries usable in every band with theta_i, theta_r <= ``theta_max`` (radians; grazing
    cells are the least reliable in a measurement) and theta_d > 0 (omega_i = omega_r: the
    table frame is undefined there) are candidates, of which ``max_points`` are drawn at random
    (``seed``; all of them if fewer).  The drawn cells are converted to the paper's angles and
    bases.  The table is read one phi_d slab at a time; ``progress`` (a callback, True for stderr lines:
    :mod:`hyde_bsdf.progress`) hears about it every few seconds.
    """
    if not isinstance(table, PbsdfTable):
        table = read_pbsdf(table)
    if not (isinstance(max_points, (int, np.integer)) and max_points >= 1):
        raise UsageError(f"max_points must be an integer >= 1, got {max_points!r}")
    if not (isinstance(theta_max, (int, float)) and 0 < theta_max <= math.pi / 2):
        raise UsageError(f"theta_max must be in (0, pi/2] radians, got {theta_max!r}")
    if not (isinstance(tolerance, (int, float)) and 0 <= tolerance <= 1):
        raise UsageError(f"tolerance must be in [0, 1], got {tolerance!r}")
    if isinstance(seed, (bool, np.bool_)) or not isinstance(seed, (int, np.integer)) or not 0 <= seed < 2**63:
        raise UsageError(f"seed must be an integer in [0, 2^63), got {seed!r}")
    om_i, om_r, x = table.grid_directions()
    up = (om_i[..., 2] > 1e-12) & (om_r[..., 2] > 1e-12)
    cand = up & (om_i[..., 2] >= math.cos(theta_max) - 1e-12) & (om_r[..., 2] >= math.cos(theta_max) - 1e-12)
    cand &= (table.theta_d > 0)[None, :, None]
    K = table.wavelengths.size
    totals = dict(total=0, below=0, nonfinite=0, nonphysical=0, usable=0)
    detail = {}
    all_bands = np.zeros(up.shape, bool)
    report = Throttle(as_callback(progress))
    label = f"reading {Path(table.source).name}"
    n_pd = table.phi_d.size
    for p in range(n_pd):
        slab = np.asarray(table.M[p], float)
        usable, nonfinite, nonphys, det = classify_cells(slab, up[p], tolerance)
        totals["total"] += usable.size
        totals["below"] += int((~up[p]).sum()) * K
        totals["nonfinite"] += int(nonfinite.sum())
        totals["nonphysical"] += int(nonphys.sum())
        totals["usable"] += int(usable.sum())
        for k, v in det.items():
            detail[k] = detail.get(k, 0) + v
        all_bands[p] = usable.all(axis=-1) & cand[p]
        report(lambda: f"{label}: {p + 1}/{n_pd} ({100 * (p + 1) / n_pd:.0f} %), {report.elapsed:.0f} s")
    counts = CellCounts(totals["total"], totals["below"], totals["nonfinite"], totals["nonphysical"],
                        totals["usable"], detail)
    where = np.argwhere(all_bands)
    if where.shape[0] == 0:
        raise PbsdfFileError(f"pBSDF file {table.source!r}: no geometry is usable in every band within "
                             f"theta <= {math.degrees(theta_max):.0f} deg ({counts.summary()})")
    rng = np.random.default_rng(seed)
    if where.shape[0] > max_points:
        where = where[np.sort(rng.choice(where.shape[0], max_points, replace=False))]
    a, b, c = where.T
    oi, orr, xt = om_i[a, b, c], om_r[a, b, c], x[a, b, c]
    M = np.asarray(table.M[a, b, c], float)               # (N, K, 4, 4)
    F = table_to_paper(np.moveaxis(M, 1, 0), oi, orr, xt)  # (K, N, 4, 4)
    ti, tr, ph, _, _ = paper_angles(oi, orr)
    return PbsdfSamples(theta_i=ti, theta_r=tr, phi=ph, F=F, wavelengths=table.wavelengths.copy(),
                        counts=counts, cells=where, source=table.source,
                        usable_geometries=int(all_bands.sum()))

