"""The floor of a truncated partition: below it sigma is the partition's artefact, not the surface's (issue 25).

Why
---
A partition of length L lit over a footprint w is cut at x = +-L/2, where the incident field (beam) or the
windowed current (window) still has the amplitude a_e = exp(-(L / 2w)^2) (e^-4 at the default L = 4w, e^-9 at
6w).  The cut radiates like an edge; in s a plane-wave-lit (windowed) partition's ends also launch surface waves
that radiate at forward grazing.  Where the surface's own sigma is not well above these, the result is a floor --
near forward grazing of a smooth or near-specular surface at 80 deg and beyond, with the default partitions.

The estimate, relative to the flat plate's specular peak sigma_0 = sqrt(2 pi) k w cos^2 ti (every term measured on
flat PEC plates at 10 pts/lambda against the analytic reflected beam, ``hyde_bsdf/validation/mom_forward_grazing.py``):

* truncation (both incidences, s and p): a_e^2 / max(1, (k w (sin theta_r - sin ti))^2), the two cut ends
  radiating like edges (the measured floor is within +0.8 dB of it at its maximum, beam and window, s and p,
  w = 20-75 lambda, ti = 30-80 deg, 4w; below it elsewhere);
* the solver (tolerance tol): tol^2 min(1, 0.1 / cos^4 ti), the field error of a residual below tol, squared
  (measured as |sqrt(sigma_tol) - sqrt(sigma_1e-7)|^2, its largest value over theta_r, at the specular peak:
  tol 1e-4 -96 / -100 / -86 dB at 30 / 60 / 70 deg, window, w = 37.5, 6w; -82 to -85 dB at 80-88 deg, beam,
  w = 37.5-300, 6w; tol 1e-3 -71 to -75 dB at 60-88 deg, beam and window, 4w and 6w; the residuals reached were
  0.3-0.9 tol.  The earlier 0.1 tol^2 / cos^4 ti overstated it by up to 50 dB at 88 deg -- flagging a rough
  surface's lobe -- and understated it by 3 dB at 60 deg, tol 1e-3);
* the beam's spectrum clipped at grazing (beam only): 0.01 exp(-(k w (1 - sin ti))^2 / 2), the power of its
  spectrum at grazing -- those plane waves light the partition's ends (measured 23-38 dB below that power, on the
  backward side, w = 20-75 lambda, ti = 80-85 deg);
* the windowed current's surface waves (window, s only): the measured worst floor at forward grazing for
  w = 37.5-75 lambda, L = 4w (-74, -60, -50, -44 dB at ti = 30, 60, 70, 80 deg, interpolated in ti, held
  beyond), times (4w / L)^3 (measured 4w -> 6w: -44.5 -> -49.9 dB at 80 deg) and (37.5 / w)^3 below
  w = 37.5 (measured at 70 deg, w = 20: -42.6 dB);
* the windowed current's coherent reflection in s (window, s only): a windowed current radiates the window's
  spectrum G(sin theta) = exp(-(k w (sin theta - sin ti))^2 / 2) with the obliquity of the current, cos^2 ti, where
  the reflected wave has cos^2 theta -- on a flat plate sigma_s = sigma_0 G against the physical
  sigma_0 G cos^2 theta / cos^2 ti (the same law as ``beam.window_bias``), a bias b = sigma_0 G |1 - cos^2 theta /
  cos^2 ti| times the coherent share exp(-(k sigma_h (cos ti + cos theta))^2), +10 dB at theta = 87 deg for ti = 80
  deg: the issue's forward-grazing excess in s.  A bias adds in power (a floor of random phase in amplitude), so
  it enters as b / (FLOOR_MARGIN (1 - 10^(-BIAS_DB / 10))): the margin then flags a bias of more than BIAS_DB = 2 dB
  (measured on flat PEC, w = 37.5 / 75 lambda, ti = 80 / 83 deg, 4w and 6w: without this term the window's s was
  reported valid at 86-89 deg 7-14 dB above the analytic reflected beam);
* observation within GRAZING_ZONE / (k w cos ti) rad of grazing is flagged outright (floor = inf).  The cause: a
  field's propagating spectrum ends at K = k (grazing) -- with the value A(k) in p, with a square-root zero
  k cos theta A in s -- so the infinite plane's current has a tail that decays only as 1/x (p), x^-3/2 (s) beyond
  the footprint; the partition cuts it at +-L/2, which convolves the current's spectrum with the partition's
  sinc (width 2 pi / L in K).  The far field at theta_r -> 90 deg samples that smoothed end: p falls towards
  half its amplitude (-6 dB), s fills its zero (an excess).  Measured against the infinite plane: p -2 to -5.7 dB,
  s +2 to +16 dB from 89 deg on, nearly independent of L (at 89 deg pi L (pi/2 - theta)^2 / 2 < 0.5 for
  L < 1000 lambda: still at the end); the cut infinite-plane current, int_{-L/2}^{L/2} J_inf(x) e^{jkx sin theta}
  dx, predicts the MoM's p to 0.1 dB and its s to 2 dB at 86-89.75 deg (flat PEC, beam, ti = 85 / 88 deg,
  w = 50 - 150 lambda, 4w and 6w; ``hyde_bsdf/validation/mom_forward_grazing.py``, ``truncated_plane_db``).

Checked: flat PEC, beam, w = 20 / 37.5 / 75 lambda, ti = 70 / 80 / 83 / 85 / 88 deg, L = 4w and 6w: every sigma
reported valid is within 2.3 dB of the analytic reflected beam (``tests/test_mom_beam.py``); at theta_r = 86-89 deg,
beam and window, s and p, ti = 80 / 83 / 85 / 87 / 88 deg, w = 37.5 / 75 / 150 / 300 lambda, L = 4w and 6w (160
cases): within 1.93 dB (``hyde_bsdf/validation/mom_forward_grazing.py``, graded at 3 dB).

sigma is reported valid where it is at least FLOOR_MARGIN times the estimate: a floor coherent with the true
field then moves sigma by at most +2.0 / -2.5 dB (within the issue's 3 dB).
"""
from __future__ import annotations

import math

import numpy as np

from hyde_bsdf.mom.kernels import K0

__all__ = ["FLOOR_MARGIN", "partition_floor", "floor_reason"]

#: sigma counts as valid where it is at least this many times the estimated floor
FLOOR_MARGIN = 20.0
#: sigma within this many beam widths (1 / (k w cos ti) rad) of grazing observation is flagged
GRAZING_ZONE = 1.5
#: the windowed current's coherent obliquity bias in s is flagged above this many dB
BIAS_DB = 2.0
#: the windowed current's s floor at forward grazing (dB below the specular peak; flat PEC, L = 4w, w >= 37.5)
_SURFACE_WAVE_TI_DEG = (30.0, 60.0, 70.0, 80.0)
_SURFACE_WAVE_DB = (-74.0, -60.0, -50.0, -44.0)


def partition_floor(theta_i, theta_r, w, partition_length, beam, pol, tol, k=K0, sigma_h=0.0):
    """Estimated floor of sigma [n_ti, n_tr] (the units of sigma) of one polarisation.

    theta_i [n_ti], theta_r [n_tr] radians; w the taper width / beam footprint and partition_length in wavelengths;
    beam: bool per theta_i (the Gaussian beam, else the windowed current); pol "s" or "p"; tol the solver's relative
    residual; sigma_h the rms height in wavelengths (the coherent share of the windowed current's bias).  The terms
    and their measurements are in the module docstring.
    """
    ti = np.atleast_1d(np.asarray(theta_i, float))[:, None]
    tr = np.atleast_1d(np.asarray(theta_r, float))[None, :]
    lit = np.atleast_1d(np.asarray(beam, bool))[:, None]
    peak = math.sqrt(2.0 * math.pi) * k * w * np.cos(ti) ** 2
    edge = math.exp(-2.0 * (partition_length / (2.0 * w)) ** 2)
    solver = tol ** 2 * np.minimum(1.0, 0.1 / np.cos(ti) ** 4)
    rel = edge / np.maximum((k * w * (np.sin(tr) - np.sin(ti))) ** 2, 1.0) + solver
    # the beam's spectrum clipped at grazing: |A(k)|^2 / |A(k sin ti)|^2 of it lights the ends along the surface
    clipped = 0.01 * np.exp(-(k * w * (1.0 - np.sin(ti))) ** 2 / 2.0)
    rel = rel + np.where(lit, clipped, 0.0)
    if pol == "s":
        wave_db = np.interp(np.degrees(ti), _SURFACE_WAVE_TI_DEG, _SURFACE_WAVE_DB)
        wave = 10.0 ** (wave_db / 10.0) * (4.0 * w / partition_length) ** 3 * max(1.0, (37.5 / w) ** 3)
        rel = rel + np.where(lit, 0.0, wave + _window_obliquity_bias(ti, tr, w, sigma_h, k))
    # observation within GRAZING_ZONE / (k w cos ti) rad of grazing: the partition cuts the current's grazing tail
    near = (math.pi / 2.0 - np.abs(tr)) * k * w * np.cos(ti) < GRAZING_ZONE
    return np.where(near, np.inf, peak * rel)


def _window_obliquity_bias(ti, tr, w, sigma_h, k):
    """The windowed current's coherent s bias relative to sigma_0, weighted so that FLOOR_MARGIN flags BIAS_DB."""
    spectrum = np.exp(-(k * w * (np.sin(tr) - np.sin(ti))) ** 2 / 2.0)
    coherent = np.exp(-(k * sigma_h * (np.cos(ti) + np.cos(tr))) ** 2)
    bias = spectrum * coherent * np.abs(1.0 - np.cos(tr) ** 2 / np.cos(ti) ** 2)
    return bias / (FLOOR_MARGIN * (1.0 - 10.0 ** (-BIAS_DB / 10.0)))


def floor_reason(w, partition_length):
    """One line: why a sigma below the floor is not the surface's."""
    return (f"below {FLOOR_MARGIN:g} x the estimated floor of the truncated partition (L = "
            f"{partition_length / w:.3g} w: the field at its ends is exp(-(L/2w)^2) = "
            f"{math.exp(-(partition_length / (2.0 * w)) ** 2):.2g} of the centre's; a windowed current in s adds the "
            "surface waves its lit ends launch and its coherent reflection's wrong obliquity, cos^2 theta_i for "
            "cos^2 theta_r, a beam the part of its spectrum clipped at grazing), or within "
            f"{GRAZING_ZONE:g} / (k w cos theta_i) rad of grazing (there the partition's cut of the current's tail, "
            "which the field's spectrum ending at grazing leaves, takes p towards -6 dB and raises s); "
            "use incidence='beam' and partitions of 6 w or more")
