"""The one optimiser of the inverse package: Adam on log(value), for :func:`~hyde_bsdf.inverse.invert`
(one global value per parameter) and :func:`~hyde_bsdf.inverse.invert_maps` (a value per texel).

Log values keep every parameter positive and let one learning rate fit values of any size; each is
clamped to its range after every step.  The learning rate is constant for the first half of the
iterations, then decays geometrically to a tenth of it; the result is the mean of the iterates over
the last ``average_last`` iterations (Polyak averaging: it cancels the Monte-Carlo jitter of single
steps).  The gradient with respect to the log value is the value's own times the value (the chain
rule, applied here, so that a frozen step, ``dr.freeze``, sees the values as plain inputs).

Moments: beta_1 = 0.8 and beta_2 = 0.9, not Adam's 0.9 / 0.999.  A texel's gradient falls by orders
of magnitude as it converges, and a long memory of the early large gradients stalls it (measured: with
0.999 the alpha = 0.6 square of the validation map sat 11 % high after 60 iterations, with 0.9 below
1 %); less momentum overshoots less where a value moves far.  The scalar inversion ran Adam's
defaults before the two were one; with these moments and this schedule its errors on the sphere of
hyde_bsdf/validation/inverse_render.py fell from +0.23 / -0.64 / -0.56 % to +0.13 / -0.28 / -0.20 % (rms_slope,
n, k; 400 iterations, the Stokes loss; docs/validation.md).
"""
from __future__ import annotations

import math

import numpy as np

__all__ = ["LogAdam", "BETA_1", "BETA_2", "check_gradients"]

BETA_1, BETA_2 = 0.8, 0.9


def check_gradients(grads: dict, iteration: int) -> None:
    """FloatingPointError naming the parameter and the iteration when a gradient is NaN or infinite
    (an optimiser step with it would turn every value into NaN)."""
    import drjit as dr

    for name, g in grads.items():
        if not bool(dr.all(dr.isfinite(g), axis=None)):
            raise FloatingPointError(f"the gradient of {name} became NaN or infinite at iteration {iteration} "
                                     f"(a reference far from what the scene can render, or a step too large)")


class LogAdam:
    """Adam on log(value) per parameter (see the module docstring).

    ``start``: name -> Dr.Jit array of start values (> 0); ``ranges``: name -> (lo, hi), both > 0.
    """

    def __init__(self, start: dict, ranges: dict, lr: float, iterations: int, average_last: int):
        import drjit as dr
        import mitsuba as mi

        self.opt = mi.ad.Adam(lr=lr, beta_1=BETA_1, beta_2=BETA_2)
        self.ranges, self.lr, self.iterations, self.average_last = dict(ranges), lr, iterations, average_last
        for name, value in start.items():
            self.opt[name] = dr.log(value)
        self.names = list(start)
        self.sums, self.n_avg = {}, 0

    def values(self) -> dict:
        """Clamp each log value into its range; the values exp(log value) as gradient-enabled leaves
        (the caller writes them into its scenes and renders)."""
        import drjit as dr

        for name in self.names:
            lo, hi = self.ranges[name]
            self.opt[name] = dr.clip(self.opt[name], math.log(lo), math.log(hi))
        values = {}
        for name in self.names:
            values[name] = dr.exp(dr.detach(self.opt[name]))
            dr.enable_grad(values[name])
        return values

    def snapshot(self, name) -> np.ndarray:
        """The current value of ``name`` (NumPy, float64)."""
        return np.exp(np.asarray(self.opt[name], dtype=np.float64))

    def step(self, it: int, values: dict) -> dict:
        """The step of iteration ``it`` from the gradients held by ``values`` (after the caller's
        ``dr.backward``); returns the iterate before the step (NumPy) and adds it to the average."""
        import drjit as dr

        if it >= self.iterations // 2:
            span = max(1, self.iterations - 1 - self.iterations // 2)
            self.opt.set_learning_rate(self.lr * 0.1 ** ((it - self.iterations // 2) / span))
        for name in self.names:
            dr.set_grad(self.opt[name], dr.grad(values[name]) * dr.detach(values[name]))
        check_gradients({n: dr.grad(self.opt[n]) for n in self.names}, it)
        current = {n: self.snapshot(n) for n in self.names}
        self.opt.step()
        if it >= self.iterations - self.average_last:
            for n in self.names:
                self.sums[n] = self.sums.get(n, 0.0) + current[n]
            self.n_avg += 1
        return current

    def average(self) -> dict:
        return {n: self.sums[n] / self.n_avg for n in self.names}
