"""A Gaussian beam as the MoM's incident field: the exact alternative to the windowed current near grazing.

Why
---
The paper's Eq. 22 lights the whole partition with a plane wave and windows the *current* by
W(x) = exp(-(x/w)^2).  A windowed current is not the current of any incident field: its far
field is the window's spectrum without the obliquity that a real reflected wave carries.  For
s on a PEC the current v = 2 j k cos(ti) W e^{-jkx sin ti} radiates |F|^2 ~ cos^2(ti) |W^(k(sin
theta - sin ti))|^2 at every theta, where the reflected wave of a beam goes to 0 as cos^2(theta):
at 80 deg incidence and 87 deg observation the windowed current is (cos 80 / cos 87)^2 = 11 (10.4 dB)
too strong, and over the lobe its power is 1 + ~0.9 tau too high in s (1 - ~0.26 tau in p),
tau = (1 + 2 tan^2 ti) / (k w cos ti)^2 (Thorsos, JASA 83, 78 (1988); :func:`window_bias`).

What
----
Here the incident field itself is tapered: the beam

    psi_inc(x, y) = int_{-k}^{k} A(K) exp(-j (K x - q y)) dK,   q = sqrt(k^2 - K^2),
    A(K) = (g / (2 sqrt(pi))) exp(-g^2 (K - k sin ti)^2 / 4),

a down-going solution of the Helmholtz equation (propagating plane waves only, so exact, unlike
Thorsos' first-order tapered wave), equal to e^{-jkx sin ti} e^{-x^2/g^2} on y = 0 as far as its
spectrum stays inside the visible range.  The unwindowed surface fields radiate the scattered field,
and sigma is normalised by the beam's power P = 2 pi int |A|^2 (q / k) dK (in |E|^2 / (2 Z0) per unit
length along z): the effective illuminated length is P / cos(ti) (g sqrt(pi/2) (1 - tau/2) while the
spectrum is inside the visible range), Eq. 23's w sqrt(pi/2) for the windowed current.  The power
that reaches a rough partition is the beam's Poynting flux through it, (1/k) int Im(psi* d psi/dn) ds.

The integral runs over K = k sin(alpha) (dK = q d alpha: the integrand vanishes at grazing), trapezoid in
alpha over the spectrum's +-8 standard deviations, with a step that resolves the phase over the partition.
"""
from __future__ import annotations

import math

import numpy as np

from hyde_bsdf.mom.kernels import K0

__all__ = ["gaussian_beam", "window_bias"]

#: standard deviations of the beam's amplitude spectrum (sqrt(2) / g in K) kept on either side
_SPREAD = 8.0
#: plane waves formed at a time (x samples: the temporaries stay small)
_CHUNK = 256


def _spectrum_nodes(theta_i, g, reach, k=K0):
    """Angles alpha, weights A(k sin alpha) k cos alpha d alpha of one beam; reach = largest |r| of the samples."""
    kx = k * math.sin(theta_i)
    half = _SPREAD * math.sqrt(2.0) / g
    lo = math.asin(max(-1.0, (kx - half) / k))
    hi = math.asin(min(1.0, (kx + half) / k))
    step = min(math.pi / (4.0 * k * reach), (hi - lo) / 64.0)
    alpha = np.linspace(lo, hi, int(math.ceil((hi - lo) / step)) + 1)
    ka = k * np.sin(alpha)
    amp = (g / (2.0 * math.sqrt(math.pi))) * np.exp(-(g * (ka - kx)) ** 2 / 4.0)
    w = amp * k * np.cos(alpha) * (alpha[1] - alpha[0])
    w[[0, -1]] *= 0.5
    return alpha, w, amp


def gaussian_beam(x, y, fp, dx, theta_i, g, k=K0):
    """The beam of footprint g at each theta_i on the surface samples.

    Parameters: x, y, fp [N] (wavelengths; the beam is centred on x = 0, y = 0), dx, theta_i [n_ti]
    radians, g the footprint (wavelengths).
    Returns (psi [N, n_ti], the incident field at the samples; flux [n_ti], the beam's power through the
    surface, (1/k) sum Im(psi* (-f' psi_x + psi_y)) dx; length [n_ti], the effective illuminated length
    P / cos(ti) that normalises sigma).
    """
    ti = np.atleast_1d(theta_i)
    reach = float(np.max(np.hypot(x, y))) + 1.0
    psi = np.zeros((x.size, ti.size), complex)
    flux = np.zeros(ti.size)
    length = np.zeros(ti.size)
    for c, t in enumerate(ti):
        alpha, w, amp = _spectrum_nodes(float(t), g, reach, k)
        dpsi = np.zeros(x.size, complex)
        for a0 in range(0, alpha.size, _CHUNK):
            sa, ca = np.sin(alpha[a0:a0 + _CHUNK]), np.cos(alpha[a0:a0 + _CHUNK])
            waves = np.exp((-1j * k) * (np.outer(x, sa) - np.outer(y, ca)))
            wc = w[a0:a0 + _CHUNK]
            psi[:, c] += waves @ wc
            # d psi/dn sqrt(1 + f'^2) = -f' psi_x + psi_y, per plane wave -j k (-f' sin a) + j k cos a
            dpsi += (waves * (1j * k) * (fp[:, None] * sa[None, :] + ca[None, :])) @ wc
        flux[c] = float(np.sum(np.imag(np.conj(psi[:, c]) * dpsi)) * dx / k)
        dk = k * np.cos(alpha) * (alpha[1] - alpha[0])
        power = 2.0 * math.pi * float(np.sum(np.abs(amp) ** 2 * np.cos(alpha) * dk))
        length[c] = power / math.cos(float(t))
    return psi, flux, length


def window_bias(theta_i, w, pol, k=K0):
    """The windowed current's power balance on a flat PEC plate: reflected over incident power (exact integral).

    The current W(x) x (plane-wave current) radiates the window's spectrum G(u) = exp(-(k w)^2 (u - sin ti)^2 / 2)
    (u = sin theta, visible |u| < 1) with obliquity cos(ti) / cos(theta) (s: EFIE current) or cos(theta) / cos(ti)
    (p: MFIE current) relative to a plane wave's, over the full spectrum's power:

        s: int_{-1}^{1} G cos(ti) / sqrt(1 - u^2) du / int G du,
        p: int_{-1}^{1} G sqrt(1 - u^2) / cos(ti) du / int G du.

    To first order s: 1 + (1 + 3 tan^2 ti) / (2 (k w cos ti)^2), p: 1 - 1 / (2 (k w cos ti)^2 cos^2 ti); near grazing
    about 1 + 0.75 tau and 1 - 0.25 tau (tau Thorsos' parameter); the exact integral is what :mod:`solver` warns
    with.  Returns the ratio per theta_i (radians, array-like).
    """
    out = []
    for t in np.atleast_1d(theta_i):
        s0, c0 = math.sin(float(t)), math.cos(float(t))
        sd = 1.0 / (k * w)
        # in theta (u = sin theta): the 1/cos singularity of s becomes d theta
        step = min(1.5e-4, 0.05 * sd / max(c0, 1e-3))
        theta = np.linspace(-math.pi / 2, math.pi / 2, min(2_000_001, int(math.pi / step) + 1))
        u = np.sin(theta)
        G = np.exp(-((u - s0) / sd) ** 2 / 2.0)
        total = sd * math.sqrt(2.0 * math.pi)
        if pol == "s":
            val = np.trapezoid(G * c0, theta)                       # du / sqrt(1 - u^2) = d theta
        else:
            val = np.trapezoid(G * np.cos(theta) ** 2 / c0, theta)  # sqrt(1 - u^2) du = cos^2 theta d theta
        out.append(val / total)
    return np.array(out)
