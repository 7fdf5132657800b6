"""Fit the rational function the plugin uses for the Beckmann Smith G1 (``hyde_bsdf/mitsuba/optics.py``,
``smith_g1_exact``) and print its coefficients.

G1(a) = 2 / (1 + erf(a) + exp(-a^2) / (a sqrt(pi))), a = cot(theta) / alpha, written stably as
1 / (1 + Lambda), Lambda = exp(-a^2) (1 / (a sqrt(pi)) - erfcx(a)) / 2 (SciPy, float64).  On [0, A_MAX]
it is fitted by R(a) = a (2 sqrt(pi) + p1 a + ... + p5 a^5) / (1 + q1 a + ... + q6 a^6) (the slope
2 sqrt(pi) at a = 0 exact), least squares on the relative error with Lawson's reweighting towards the
minimax fit; beyond A_MAX, 1 - G1 < 2e-11 and the plugin returns 1.  The maximum relative error,
printed, is about 1.3e-7: float32's own rounding (the plugin computes in float32).  Dr.Jit's erf and
exp, which the closed form needs, trace 145 operations and about 40 us of host time per call; the
rational function traces 14 (``benchmarks/bench_render.py --instances`` measures the render).
``tests/test_plugin_evaluator.py`` checks the shipped coefficients against SciPy.

    .venv/bin/python tools/fit_smith_g1.py
"""
from __future__ import annotations

import numpy as np
from scipy.optimize import least_squares
from scipy.special import erfcx

A_MAX = 4.3
DEGREE = 6


def smith_g1(a):
    """The exact Beckmann Smith G1 at a = cot(theta) / alpha > 0 (float64)."""
    lam = np.exp(-a * a) * (1.0 / (a * np.sqrt(np.pi)) - erfcx(a)) / 2.0
    return 1.0 / (1.0 + lam)


def rational(num, den, a):
    """a (2 sqrt(pi) + num[0] a + ...) / (1 + den[0] a + ...), Horner (the plugin's evaluation order)."""
    p = 0.0
    for c in reversed(num):
        p = p * a + c
    p = p * a + 2.0 * np.sqrt(np.pi)
    q = 0.0
    for c in reversed(den):
        q = q * a + c
    q = q * a + 1.0
    return a * p / q


def fit(seed: int = 1, starts: int = 30):
    a = np.concatenate([np.geomspace(1e-7, 0.02, 300), np.linspace(0.02, A_MAX, 6000)])
    y = smith_g1(a)
    split = DEGREE - 1
    best = None
    rng = np.random.default_rng(seed)
    for _ in range(starts):
        p = rng.uniform(0.0, 2.0, 2 * DEGREE - 1)
        w = np.ones_like(a)
        try:
            for _ in range(8):
                p = least_squares(lambda q: w * (rational(q[:split], q[split:], a) - y) / y, p, method="lm",
                                  max_nfev=4000, xtol=1e-15, ftol=1e-15).x
                err = np.abs(rational(p[:split], p[split:], a) - y) / y
                w = w * (1.0 + (err / err.max()) ** 2)
        except (ValueError, FloatingPointError):
            continue
        den = np.r_[1.0, p[split:]]
        if not np.all(np.isfinite(p)) or np.any((r := np.roots(den[::-1])).imag == 0) and np.any(r.real[r.imag == 0] > 0):
            continue            # a pole on a > 0
        err = np.max(np.abs(rational(p[:split], p[split:], a) - y) / y)
        if best is None or err < best[0]:
            best = (err, p[:split], p[split:])
    return best


if __name__ == "__main__":
    err, num, den = fit()
    dense = np.linspace(1e-7, A_MAX, 400_000)
    dense_err = np.max(np.abs(rational(num, den, dense) - smith_g1(dense)) / smith_g1(dense))
    print(f"max relative error {err:.3g} on the fit's nodes, {dense_err:.3g} on 4e5 points of (0, {A_MAX}]; "
          f"1 - G1({A_MAX}) = {1 - smith_g1(A_MAX):.2g}")
    print("G1_NUM =", tuple(float(c) for c in num))
    print("G1_DEN =", tuple(float(c) for c in den))
