"""Evaluate a Mitsuba BSDF at the paper's angles and express it in the paper's Stokes bases.

Used by the plugin tests and validation scripts to compare the ``hyde`` plugin
(Mitsuba's implicit Stokes bases) with :func:`hyde_bsdf.pbrdf` (the paper's bases).

Geometry (COMMON.md conventions): with phi_i the incident azimuth,
omega_i = (sin ti cos phi_i, sin ti sin phi_i, cos ti) points to the source and
omega_r = (sin tr cos phi_r, sin tr sin phi_r, cos tr), phi_r = phi_i + phi, to the
observer.  Propagation directions k_i = -omega_i, k_r = omega_r; each wave's
paper basis has s = normalize(k x z) (the limit at fixed azimuth at theta = 0,
i.e. s_i = (-sin phi_i, cos phi_i, 0), s_r = (sin phi_r, -cos phi_r, 0)) and
p = k x s.

Mitsuba side: in Radiance mode ``si.wi = omega_r`` and ``wo = omega_i``; in
Importance mode ``si.wi = omega_i`` and ``wo = omega_r``.  Either way the BSDF's
Mueller matrix maps ``stokes_basis(k_i)`` to ``stokes_basis(k_r)``, and
``eval`` returns f cos(theta of wo).  :func:`eval_paper` rotates those bases into
the paper's with ``mi.mueller.rotate_mueller_basis`` and divides the cosine out.
"""
from __future__ import annotations

import numpy as np

__all__ = ["paper_geometry", "eval_paper", "random_angles"]


def paper_geometry(theta_i, theta_r, phi, phi_i=0.0):
    """omega_i, omega_r, s_i, s_r as float64 arrays [N, 3] (see module docstring)."""
    ti, tr, ph, pi_ = np.broadcast_arrays(*(np.atleast_1d(np.asarray(x, float))
                                            for x in (theta_i, theta_r, phi, phi_i)))
    pr = pi_ + ph
    om_i = np.stack([np.sin(ti) * np.cos(pi_), np.sin(ti) * np.sin(pi_), np.cos(ti)], -1)
    om_r = np.stack([np.sin(tr) * np.cos(pr), np.sin(tr) * np.sin(pr), np.cos(tr)], -1)
    s_i = np.stack([-np.sin(pi_), np.cos(pi_), np.zeros_like(pi_)], -1)
    s_r = np.stack([np.sin(pr), -np.cos(pr), np.zeros_like(pr)], -1)
    return om_i, om_r, s_i, s_r


def angles_of(om_i, om_r):
    """(theta_i, theta_r, phi, phi_i) in float64 of (possibly float32-rounded) directions."""
    om_i = np.asarray(om_i, float)
    om_r = np.asarray(om_r, float)
    om_i = om_i / np.linalg.norm(om_i, axis=-1, keepdims=True)
    om_r = om_r / np.linalg.norm(om_r, axis=-1, keepdims=True)
    ti = np.arccos(np.clip(om_i[..., 2], -1, 1))
    tr = np.arccos(np.clip(om_r[..., 2], -1, 1))
    pi_ = np.arctan2(om_i[..., 1], om_i[..., 0])
    pr = np.arctan2(om_r[..., 1], om_r[..., 0])
    return ti, tr, np.mod(pr - pi_, 2 * np.pi), pi_


def random_angles(n, rng, theta_max=np.radians(89.0)):
    """n random (theta_i, theta_r, phi, phi_i), cosine-weighted-ish polar angles up to theta_max."""
    ti = np.arccos(rng.uniform(np.cos(theta_max), 1.0, n))
    tr = np.arccos(rng.uniform(np.cos(theta_max), 1.0, n))
    ph = rng.uniform(0, 2 * np.pi, n)
    pi_ = rng.uniform(0, 2 * np.pi, n)
    return ti, tr, ph, pi_


def _first_channel(x, n, jit):
    """UnpolarizedSpectrum / Color3f / Float value -> [n] float64 of its first channel."""
    arr = np.array(x, dtype=float)
    return arr.reshape(-1, n)[0] if jit else arr.reshape(-1)[:1]


def eval_paper(bsdf, om_i, om_r, s_i, s_r, *, wavelength=550.0, mode="radiance"):
    """The BSDF's F (1/sr, NOT times cos) at the given directions, in the paper's bases.

    Arguments are float64 arrays [N, 3] (directions are rounded to float32 on the
    way into Mitsuba).  Returns float64 [N, 4, 4] in polarized variants, [N] (the
    first colour/wavelength channel of F_00) in unpolarized ones.  Works in
    scalar (a Python loop) and JIT (vectorised) variants.
    """
    import drjit as dr
    import mitsuba as mi

    from hyde_bsdf.mitsuba.optics import aligned_float32

    om_i = np.atleast_2d(om_i)
    om_r = np.atleast_2d(om_r)
    s_i = np.atleast_2d(s_i)
    s_r = np.atleast_2d(s_r)
    n = om_i.shape[0]
    ctx = mi.BSDFContext(mi.TransportMode.Radiance if mode == "radiance" else mi.TransportMode.Importance)
    polarized = mi.is_polarized

    jit = dr.is_jit_v(mi.Float)

    def V(a):
        if jit:
            return mi.Vector3f(*(mi.Float(aligned_float32(a[:, j])) for j in range(3)))
        return mi.Vector3f(*(float(a[0, j]) for j in range(3)))

    def one_batch(oi, orr, si_ax, sr_ax):
        wi_dir = V(orr) if mode == "radiance" else V(oi)
        wo_dir = V(oi) if mode == "radiance" else V(orr)
        si = dr.zeros(mi.SurfaceInteraction3f)
        si.wi = wi_dir
        if mi.is_spectral:
            si.wavelengths = mi.UnpolarizedSpectrum(wavelength)
        value = bsdf.eval(ctx, si, wo_dir)
        cos_o = np.asarray(oi[:, 2] if mode == "radiance" else orr[:, 2], float)
        if not polarized:
            return _first_channel(value, len(cos_o), jit) / cos_o
        k_in = -V(oi)
        k_out = V(orr)
        M = mi.mueller.rotate_mueller_basis(
            value, k_in, mi.mueller.stokes_basis(k_in), V(si_ax),
            k_out, mi.mueller.stokes_basis(k_out), V(sr_ax))
        dr.eval(M)   # one kernel for all 16 entries
        out = np.empty((len(cos_o), 4, 4))
        for r in range(4):
            for c in range(4):
                out[:, r, c] = _first_channel(M[r, c], len(cos_o), jit)
        return out / cos_o[:, None, None]

    if jit:
        return one_batch(om_i, om_r, s_i, s_r)
    parts = [one_batch(om_i[j:j + 1], om_r[j:j + 1], s_i[j:j + 1], s_r[j:j + 1]) for j in range(n)]
    return np.concatenate(parts, axis=0)
