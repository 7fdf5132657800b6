"""Per-texel standard errors of fitted parameter maps from the Gauss-Newton (Fisher) information of
the Stokes loss, a Gauss-Newton polishing step, and the warning for parameters the data do not
determine.

Model.  The fit minimises L(theta) = sum_i w_i (S_i(theta) - R_i)^2 over pixels i and Stokes
components (:class:`~hyde_bsdf.inverse.loss.StokesLoss`: w = mask / (pixels x norm) per component and
observation).  With the reference R_i = S_i(theta*) + e_i, Var(e_i) = sigma_i^2, the linearised
least-squares estimate has the sandwich covariance

    Cov(theta_hat) = A^-1 B A^-1,   A = sum_i w_i J_i J_i^T,   B = sum_i w_i^2 sigma_i^2 J_i J_i^T

(A: the Gauss-Newton matrix of the loss; with w_i = 1 / sigma_i^2 it is the Fisher information and
Cov = A^-1).  The polishing steps and the standard errors after them use w_i = 1 / sigma_i^2 (per
observation and Stokes component: ``weighting="fisher"`` of :func:`information_blocks`), so the
result is the efficient weighted least-squares estimate and Cov = A^-1; the loss's own weights
(each Stokes term normalised by its reference's energy) are kept only for an unpolished Adam
result (``polish=0``), whose covariance is then the sandwich.  (The loss's normalisation weighs the
S1 of an unpolarized picture, S1 << S0, up to ~1000x above its noise: on a texel of the 7-picture
metal design the standard error of n was 4.6 % with the loss's weights and 1.5 % with the Fisher
weights -- what the NumPy model's Fisher information gives, test_inverse_capture.py.)  J_i = dS_i / d log(theta): parameters are log values, so the standard errors are
relative.  With nearest-neighbour textures a pixel depends only on the texels its footprint covers.
One forward-mode AD pass per parameter -- tangent theta (that is, d log theta = 1) on every texel at
once -- gives sum_t dS_i / d log theta_t, which for a pixel whose footprint lies inside one texel
(all SUB x SUB camera sub-samples of :func:`~hyde_bsdf.inverse.observations.pixel_texels` in it) is
exactly dS_i / d log theta_t (the sub-samples include the pixel's border,
:func:`~hyde_bsdf.inverse.observations.pixel_texels` with ``edges=True``, so a pure pixel lies wholly
inside the texel).  The information and the polishing steps use those *pure* pixels only:
the information is then exactly block-diagonal per texel (P x P blocks for P fitted maps), and the
standard errors are slightly conservative (the pixels straddling texel edges, which the fit also
uses, are left out).  Splitting a straddling pixel's derivative by its sub-sample shares instead was
measured wrong where neighbours differ (a sharp alpha edge 0.12 | 0.48: pulls of -8 to -18 at the
edge texels), so it is not done.  Texels need a few pixels across in some view to get any: a seen
texel with no whole pixel in any picture gets NaN standard errors and a warning of its own (its value is
fitted, its uncertainty unknown), apart from "not determined".

Noise.  ``noise`` (the standard deviation of the reference's Stokes components: one number, or per
observation a number or 4 numbers S0..S3) if the caller knows it; otherwise sigma^2 is estimated per observation and component from
the residuals at the solution, mean(r^2) x n / (n - p) over the pure pixels, with the Monte-Carlo
variance of the rendering itself (from a second render with another seed, on the same pixels)
subtracted (reported as ``noise``; a pixel straddling two texels has a sampling noise of the order
of their difference, which is not the noise of the pixels used).  The polishing step uses the residual of a render with its own sampling noise, so B
uses the reference's variance plus that render's.

Polishing.  Gauss-Newton steps per texel, d = -(A + 1e-6 tr(A)/P) ^-1 g (g = sum w J r, half the loss
gradient in log parameters; each component clipped to +-``max_step``), move the Adam iterate (which
still carries the jitter of its few-sample renders, and lags where a texel had far to go) to the
least-squares solution that the covariance describes.

Identifiability.  A parameter is *not determined* in a texel when its relative standard error
exceeds :data:`STDERR_THRESHOLD` (10 %: the data then fix it no better than a guess would).
:func:`identification_warnings` names the parameter and the fraction of seen texels affected, and
:func:`~hyde_bsdf.inverse.maps.invert_maps` issues them as :class:`UnidentifiedParameterWarning`.

Convergence before uncertainty.  The standard errors describe the scatter of the *minimum* of the
weighted least squares; an iterate that has not reached it is off by more than they say (measured
on the full validation map stopped at 40 of 120 Adam iterations: pull std 7.9 for alpha, 5.0 for
eta, no warning).  So before they are reported, :func:`convergence_test` measures, per texel and
parameter, the last Gauss-Newton step in standard errors, |d_p| / se_p (with polishing: the step
last applied; without: the step the blocks predict at the result, -A^-1 g, that is the gradient
against the noise scale).  Newton's method converges quadratically, so a minimum reached leaves a
last step of the order of the step's own sampling jitter (< 1 standard error); a larger one means
the texel was still moving.  Where it exceeds :data:`CONVERGENCE_THRESHOLD` standard errors, or the
step hit its clip, the texel's parameter is *not converged*.  Small steps cannot show a texel that
the steps no longer move (stuck in a local minimum or at a bound: in the quick stopped-early run an
eta texel 10 standard errors off kept its standard error), so the gradient is also measured against
the noise the other way, by what it leaves: a texel whose residuals stay above the noise (chi-square
p-value < :data:`MISFIT_P`, :func:`texel_misfit`) or whose value sits at a bound of its range is not
converged, and neither is any parameter of a texel not converged in one
(:func:`texel_convergence`).  A not-converged texel's standard error is set to NaN (never
left as a small number), ``Uncertainty.converged`` marks it False, and
:func:`convergence_warnings` names the parameter, the fraction of texels and the largest step
(:class:`NotConvergedWarning`).
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from hyde_bsdf.errors import UsageError, shorten
from hyde_bsdf.inverse._common import NotConvergedWarning
from hyde_bsdf.inverse.observations import pixel_texels, render_stokes

__all__ = ["STDERR_THRESHOLD", "CONVERGENCE_THRESHOLD", "UnidentifiedParameterWarning", "NotConvergedWarning",
           "BilinearFilterWarning",
           "Uncertainty", "convergence_test", "convergence_warnings", "MISFIT_P", "misfit_pvalues",
           "texel_convergence", "at_bounds", "texel_misfit", "stokes_tangents",
           "information_blocks", "pixel_records", "accumulate_blocks", "standard_errors", "gauss_newton_step", "identification_warnings"]

#: relative standard error above which a parameter counts as not determined in a texel
STDERR_THRESHOLD = 0.10
#: the last Gauss-Newton step, in standard errors, above which a texel's parameter counts as not converged
CONVERGENCE_THRESHOLD = 3.0
#: a texel whose residuals noise alone would leave this rarely (chi-square p-value) counts as not converged
MISFIT_P = 1e-3
#: camera sub-samples per pixel side of the pixel -> texel shares
SUB = 4


class UnidentifiedParameterWarning(UserWarning):
    """A fitted parameter map that the data do not determine in some texels."""


class BilinearFilterWarning(UserWarning):
    """A fitted bitmap filters bilinearly: :func:`~hyde_bsdf.inverse.invert_maps` switches it to
    nearest (or, for a BSDF that cannot take the swap, sets the standard errors to NaN: the per-texel
    ones do not hold for a pixel that blends 4 texels)."""


@dataclass
class Uncertainty:
    """Per-texel standard errors of fitted maps (NaN where no image sees the texel)."""

    names: tuple
    stderr: dict                          # name -> (rows, cols) absolute standard error
    rel_stderr: dict                      # name -> (rows, cols) standard error of log(value)
    A: np.ndarray                         # (texels, P, P) Gauss-Newton matrix (log parameters)
    B: np.ndarray                         # (texels, P, P) noise term of the sandwich
    gradient: np.ndarray                  # (texels, P) loss gradient (log parameters)
    noise: list = field(default_factory=list)        # per observation: (4,) reference noise std
    unidentified: dict = field(default_factory=dict)  # name -> fraction of seen texels above threshold
    threshold: float = STDERR_THRESHOLD
    step_se: dict = field(default_factory=dict)       # name -> (rows, cols) last Gauss-Newton step / stderr
    converged: dict = field(default_factory=dict)     # name -> (rows, cols) bool (False: stderr set to NaN)
    filter_valid: bool = True                         # False: a bilinear bitmap; every stderr set to NaN
    messages: list = field(default_factory=list)      # (warning category, message), each once
    unchecked: dict = field(default_factory=dict)     # name -> rel_stderr before the convergence/filter checks
    misfit_p: np.ndarray | None = None                # (rows, cols) chi-square p-value of the texel's residuals
    pinned: dict = field(default_factory=dict)        # name -> (rows, cols) bool: the value sits at a bound


def stokes_tangents(scene, params, keys: dict, names, sensor: int, spp: int, seed: int, channels=None):
    """Stokes images S (4, H, W) and their tangents dS/dlog(theta) (P, 4, H, W) for the map
    parameters ``names`` (``keys[name]``: the traverse key of its texture data), one forward-mode
    pass each with the same ``seed`` (so every pass renders the same primal samples)."""
    import drjit as dr
    import mitsuba as mi

    tangents, S = [], None
    for name in names:
        x = mi.TensorXf(dr.detach(params[keys[name]]))
        dr.enable_grad(x)
        params[keys[name]] = x
        params.update()
        img = render_stokes(scene, sensor, spp, seed, params=params, names=channels)
        dr.set_grad(x, dr.detach(x))          # d theta = theta: a unit step in log(theta) on every texel
        dr.forward_from(x)
        tangents.append(np.array([np.asarray(dr.grad(s), dtype=np.float64) for s in img]))
        if S is None:
            S = np.array([np.asarray(dr.detach(s), dtype=np.float64) for s in img])
        params[keys[name]] = dr.detach(x)
        params.update()
    return S, np.array(tangents)


def _weights(loss, obs_weight: float):
    """Per component (4,) weight maps of a StokesLoss: w = obs_weight * (the loss's weights) / pixels."""
    return obs_weight * loss.weights_np / loss.mask_np.size


def information_blocks(problem, names, *, spp: int = 16, seed: int = 0, noise=None, weighting: str = "fisher"):
    """Accumulate the per-texel blocks A, B (texels, P, P) and g = sum_i w_i J_i r_i (texels, P; r = S - R)
    over the observations of a :class:`~hyde_bsdf.inverse.maps.MapProblem` at its current values.

    ``weighting="loss"``: w_i the loss's weights (A is half the loss's Gauss-Newton Hessian, g half its
    gradient; A^-1 B A^-1 is the covariance of the loss's minimiser).  ``weighting="fisher"``: w_i =
    1 / sigma_i^2 (the reference's variance plus the render's, per observation and Stokes component):
    A = B is the Fisher information, A^-1 the covariance of the weighted least-squares estimate that
    Gauss-Newton steps with these blocks converge to -- the efficient one.  The two differ where the
    loss weighs components unlike their noise: the Stokes loss normalises S1..S3 by their own energy,
    which for an unpolarized picture (S1 small, S2 = S3 = 0) weighs its S1 thousands of times above
    its noise (measured on the metal design: n's standard error 4.6 % with the loss's weights, 1.5 %
    with the Fisher weights, on a texel with 3-9 pixels per picture).

    Returns (A, B, g, noise_std per observation, number of data values n)."""
    if weighting not in ("fisher", "loss"):
        raise UsageError(f"weighting must be 'fisher' or 'loss', got {shorten(weighting)}")
    records = pixel_records(problem, names, spp=spp, seed=seed, noise=noise)
    return accumulate_blocks(records, problem.map_shape, len(names), weighting=weighting)


def pixel_records(problem, names, *, spp: int = 16, seed: int = 0, noise=None) -> list:
    """Per observation, what the blocks are built from, on the pixels lying wholly inside one texel:
    a dict with ``t`` (texel of each pixel), ``J`` (P, 4, pixels) = dS/dlog(theta_t), ``r`` (4, pixels)
    = S - R, ``w`` (4, pixels) the loss's weights, ``mc_var`` (4,) the render's sampling variance,
    ``ref_var`` (4,) the reference's variance when ``noise`` gives it (else None: estimated from the
    residuals), ``comps`` (the indices of the components in the loss), ``obs_weight``, ``s0_power`` (mean S0^2).
    None for an observation with no such pixel."""
    rows, cols = problem.map_shape
    T, P = rows * cols, len(names)
    records = []
    for j, (o, loss) in enumerate(zip(problem.observations, problem.losses)):
        si = problem.scene_of[j]
        scene, params, keys = problem.scenes[si], problem.all_params[si], problem.keys[si]
        S, J = stokes_tangents(scene, params, keys, names, o.sensor, spp, seed + 2 * j, problem.channels[j])
        S2 = np.array([np.asarray(s, dtype=np.float64) for s in
                       render_stokes(scene, o.sensor, spp, seed + 2 * j + 1, names=problem.channels[j])])
        mask = loss.mask_np
        r = S - loss.ref_np
        pix, tex = pixel_texels(o, (rows, cols), problem.prefix, sub=SUB, edges=True)
        key, counts = np.unique(pix.astype(np.int64) * T + tex, return_counts=True)
        pure = counts == SUB * SUB            # the whole pixel lies in this one texel
        p_i, t_i = key[pure] // T, key[pure] % T
        H, W = mask.shape
        if p_i.size == 0:                     # no pixel inside one texel: no information from this picture
            records.append(None)
            continue
        # the variances on the pixels that enter the information: a pixel straddling two texels has a
        # sampling noise of the order of the texels' difference, which is not these pixels' noise
        Sf, S2f = S.reshape(4, H * W)[:, p_i], S2.reshape(4, H * W)[:, p_i]
        ref_var = None
        if noise is not None:
            nj = noise if np.ndim(noise) == 0 else noise[j]          # one number for all, or one per observation
            ref_var = np.broadcast_to(np.asarray(nj, np.float64) ** 2, (4,)).copy()
        elif loss.sigma_np is not None:                              # the reference's own sigma maps
            ref_var = loss.sigma_np.reshape(4, H * W)[:, p_i] ** 2
        records.append(dict(t=t_i, J=J.reshape(P, 4, H * W)[:, :, p_i], r=r.reshape(4, H * W)[:, p_i],
                            w=_weights(loss, problem.weights[j]).reshape(4, H * W)[:, p_i],
                            mc_var=np.mean((Sf - S2f) ** 2, axis=1) / 2.0, ref_var=ref_var,
                            comps=loss.active, obs_weight=problem.weights[j],
                            s0_power=float(np.mean(Sf[0] ** 2))))
    return records


def accumulate_blocks(records, map_shape, P: int, *, weighting: str = "fisher", step=None):
    """A, B, g, noise, n (see :func:`information_blocks`) from :func:`pixel_records`.  ``step``
    (texels, P): a Gauss-Newton step in log parameters already decided; the residuals are then the
    linearised ones after it, r + J d -- what the reference's noise is estimated from when it is
    not given (the residuals before a step carry the misfit the step removes, which would inflate
    the noise estimate and the standard errors: measured 15-30 % against 1 % on a 4 x 4 map 10
    iterations from its start)."""
    T = int(map_shape[0]) * int(map_shape[1])
    A = np.zeros((T, P, P))
    B = np.zeros((T, P, P))
    g = np.zeros((T, P))
    noise_out = []
    n_data = 0
    for rec in records:
        if rec is None:
            noise_out.append(np.full(4, np.nan))
            continue
        t_i, Jf = rec["t"], rec["J"]
        rf, ref_var, total_var = _residual_variance(rec, step)
        n_pix, comps = t_i.size, rec["comps"]
        noise_out.append(np.sqrt(ref_var if np.ndim(ref_var) == 1 else np.mean(ref_var, axis=1)))
        n_data += n_pix * len(comps)
        wf = _fisher_weights(rec, total_var) if weighting == "fisher" else rec["w"]
        for c in comps:
            jc = Jf[:, c, :]                              # (P, pixels): d S_i / d log theta_t
            outer = np.einsum("ak,bk->kab", jc, jc)
            np.add.at(A, t_i, wf[c][:, None, None] * outer)
            np.add.at(B, t_i, (wf[c] ** 2 * total_var[c])[:, None, None] * outer)
            np.add.at(g, t_i, (wf[c] * rf[c])[:, None] * jc.T)
    return A, B, g, noise_out, n_data


def _residual_variance(rec, step=None):
    """(r, ref_var, total_var) of one :func:`pixel_records` record: the residuals (4, pixels), linearised
    after ``step`` (texels, P) when given; the reference's variance ((4,) or (4, pixels); estimated from
    the residuals less the render's sampling variance when not known); the total variance (4, pixels)
    = the reference's + the render's own (the polishing render's noise enters the residual)."""
    rf = rec["r"]
    if step is not None:
        rf = rf + np.einsum("pcn,np->cn", rec["J"], np.asarray(step)[rec["t"]])
    mc_var = np.asarray(rec["mc_var"])
    if rec["ref_var"] is not None:
        ref_var = rec["ref_var"]           # (4,) per component, or (4, pixels) from sigma maps
    else:
        ref_var = np.maximum(np.mean(rf ** 2, axis=1) - mc_var, 0.0)
    total_var = np.broadcast_to(np.reshape(ref_var, (4, -1)), (4, rec["t"].size)) + mc_var[:, None]
    return rf, ref_var, total_var


def _fisher_weights(rec, total_var):
    """1 / variance per component and pixel (floored far below any camera's noise: a noiseless
    synthetic component must not divide by zero; 0 for an observation of weight 0)."""
    floor = 1e-12 * max(rec["s0_power"], 1e-30)
    return (1.0 if rec["obs_weight"] > 0 else 0.0) / np.maximum(total_var, floor)


def texel_misfit(records, map_shape, step=None):
    """Per texel (texels,): chi2 = sum of (r / sigma)^2 over its whole pixels and the loss's components
    (the residuals linearised after ``step``, sigma^2 the total variance of :func:`_residual_variance`),
    and the number of data values m.  At the least-squares minimum chi2 scatters like a chi-square of
    about m degrees of freedom; a texel held away from it (at a bound, in a local minimum, or where
    the model cannot describe its pixels) keeps residuals above the noise."""
    T = int(map_shape[0]) * int(map_shape[1])
    chi2, m = np.zeros(T), np.zeros(T)
    for rec in records:
        if rec is None or not rec["obs_weight"] > 0:
            continue
        rf, _, total_var = _residual_variance(rec, step)
        w = _fisher_weights(rec, total_var)
        for c in rec["comps"]:
            np.add.at(chi2, rec["t"], w[c] * rf[c] ** 2)
            np.add.at(m, rec["t"], 1.0)
    return chi2, m


def standard_errors(A, B, seen=None, dof=None):
    """Relative standard errors (texels, P): sqrt(diag(A^-1 B A^-1)); inf where A is singular.

    ``dof``: (n, p) -- B is scaled by n / (n - p) (residual degrees of freedom)."""
    T, P = A.shape[0], A.shape[1]
    out = np.full((T, P), np.nan)
    scale = 1.0
    if dof is not None and dof[0] > dof[1]:
        scale = dof[0] / (dof[0] - dof[1])
    idx = range(T) if seen is None else np.flatnonzero(np.asarray(seen).ravel())
    for t in idx:
        a = A[t]
        tr = np.trace(a)
        if not tr > 0:
            out[t] = np.inf
            continue
        ev, V = np.linalg.eigh(a)
        good = ev > 1e-10 * ev.max()
        inv = (V[:, good] / ev[good]) @ V[:, good].T
        cov = inv @ (B[t] * scale) @ inv
        se = np.sqrt(np.maximum(np.diag(cov), 0.0))
        # a direction with no information: the parameters in it are not determined at all
        if not good.all():
            weak = np.abs(V[:, ~good]).max(axis=1) > 1e-3
            se = np.where(weak, np.inf, se)
        out[t] = se
    return out


def gauss_newton_step(A, g, seen=None, max_step: float = 0.1):
    """Per texel d = -(A + 1e-6 tr(A)/P I)^-1 g (log parameters; g = sum w J r is half the loss gradient,
    A half its Gauss-Newton Hessian), each component clipped to +-max_step."""
    T, P = g.shape
    d = np.zeros((T, P))
    idx = range(T) if seen is None else np.flatnonzero(np.asarray(seen).ravel())
    for t in idx:
        tr = np.trace(A[t])
        if not tr > 0:
            continue
        d[t] = -np.linalg.solve(A[t] + 1e-6 * tr / P * np.eye(P), g[t])
    return np.clip(d, -max_step, max_step)


def identification_warnings(rel_stderr: dict, seen, threshold: float = STDERR_THRESHOLD) -> dict:
    """{name: (fraction of seen texels with relative standard error > threshold, message)} for every
    parameter where that fraction is > 0 or where some seen texel has no standard error at all (NaN:
    no picture has a whole pixel inside it, so its information was not computed -- that is said
    apart, since the data may well determine the value there)."""
    out = {}
    seen = np.ones_like(next(iter(rel_stderr.values())), bool) if seen is None else np.asarray(seen, bool)
    n = int(seen.sum())
    for name, rel in rel_stderr.items():
        r = np.asarray(rel)[seen]
        unknown = np.isnan(r)
        bad = r > threshold                       # inf included: a texel whose pixels carry no information
        frac = float(bad.mean()) if n else 0.0
        parts = []
        if frac > 0:
            med = float(np.median(r[~unknown]))      # frac > 0: some texels have a standard error
            parts.append(f"{name} is not determined by the data in {_percent(frac)} % of the {n} seen texels "
                         f"(relative standard error > {100 * threshold:g} %; median {100 * med:.3g} %): "
                         f"its values there are not measurements")
        if unknown.any():
            parts.append(f"{name}: no standard error in {_percent(unknown.mean())} % of the {n} seen texels "
                         f"(no picture has a whole pixel inside them; give some view >= 2 pixels per texel): "
                         f"their values are fitted but their uncertainty is unknown")
        if parts:
            out[name] = (frac, "; ".join(parts))
    return out


def convergence_test(step, rel, seen=None, threshold: float = CONVERGENCE_THRESHOLD, clip=None):
    """(texels, P) bool, True where converged: |step| <= threshold x rel (both in log parameters:
    ``step`` the last Gauss-Newton step, ``rel`` the relative standard errors) and the step did not
    hit its ``clip``.  Texels outside ``seen`` or without a standard error (NaN) count as converged
    (they are reported apart).  Also returns |step| / rel."""
    step = np.abs(np.asarray(step, np.float64))
    rel = np.asarray(rel, np.float64)
    with np.errstate(divide="ignore", invalid="ignore"):
        ratio = np.where(rel > 0, step / rel, np.where(step > 0, np.inf, 0.0))
    bad = ratio > threshold
    if clip is not None:
        bad |= step >= clip * (1 - 1e-9)
    bad &= np.isfinite(rel)
    if seen is not None:
        bad &= np.asarray(seen, bool).reshape(-1, 1)
    return ~bad, ratio


def misfit_pvalues(chi2, m, P: int):
    """Per texel, the chance that noise alone leaves a chi2 (:func:`texel_misfit`) this large: the
    chi-square survival function at m - P degrees of freedom (NaN where m <= P)."""
    from hyde_bsdf.fit.adequacy import chi2_sf

    chi2, m = np.asarray(chi2, np.float64), np.asarray(m, np.float64)
    dof = m - P
    with np.errstate(invalid="ignore"):
        return np.where(dof > 0, chi2_sf(chi2, np.maximum(dof, 1.0)), np.nan)


def texel_convergence(steps, rel, seen, *, threshold: float = CONVERGENCE_THRESHOLD, clip=None,
                      misfit_p=None, pinned=None, p_min: float = MISFIT_P):
    """(texels, P) bool converged, and the largest |step| / rel, from four tests per texel:

    - each of ``steps`` (the last Gauss-Newton steps, log parameters) within ``threshold`` standard
      errors and below ``clip`` (:func:`convergence_test`);
    - ``pinned`` (texels, P): the value sits at a bound of its range (the least-squares minimum the
      covariance describes is an interior one);
    - ``misfit_p`` (texels,): the texel's residuals are not above the noise (p >= ``p_min``,
      :func:`misfit_pvalues`) -- a texel the steps no longer move, stuck in a local minimum or held
      by a bound, keeps residuals above the noise where small steps cannot tell it from converged
      (measured: an eta texel 10 standard errors off after steps < 3 standard errors had p = 8e-4,
      the converged fit's texels p >= 2.5e-3 on the quick 4 x 4 map);
    - jointly: a texel not converged in one parameter is not converged in any (far from the
      minimum in one parameter, the linearisation does not vouch for the others' small steps: that
      eta texel's alpha was 20 % off).

    Texels outside ``seen`` or without a standard error (NaN) count as converged (reported apart)."""
    ok, ratio = np.ones(np.shape(rel), bool), np.zeros(np.shape(rel))
    for d in steps:
        ok_d, r_d = convergence_test(d, rel, seen, threshold, clip=clip)
        ok &= ok_d
        ratio = np.maximum(ratio, r_d)
    if pinned is not None:
        ok &= ~np.asarray(pinned, bool)
    bad = ~ok.all(axis=1)
    if misfit_p is not None:
        bad |= np.asarray(misfit_p) < p_min
    judged = np.isfinite(np.asarray(rel, np.float64))
    if seen is not None:
        judged &= np.asarray(seen, bool).reshape(-1, 1)
    return ~(bad[:, None] & judged), ratio


def at_bounds(values, bounds, rtol: float = 1e-6):
    """(texels, P) bool: ``values`` (texels, P) at the lower or upper bound of ``bounds`` (per column
    (lo, hi)), to ``rtol``."""
    values = np.asarray(values, np.float64)
    lo = np.array([b[0] for b in bounds])
    hi = np.array([b[1] for b in bounds])
    return (values <= lo * (1 + rtol)) | (values >= hi * (1 - rtol))


def convergence_warnings(converged: dict, step_se: dict, seen, threshold: float = CONVERGENCE_THRESHOLD,
                         regularized: bool = False) -> dict:
    """{name: (fraction of seen texels not converged, message)} for every parameter with some."""
    out = {}
    seen = np.ones_like(next(iter(converged.values())), bool) if seen is None else np.asarray(seen, bool)
    n = int(seen.sum())
    for name, ok in converged.items():
        bad = ~np.asarray(ok, bool)[seen]
        if not bad.any():
            continue
        worst = float(np.max(np.asarray(step_se[name])[seen][bad]))
        cause = ("the regulariser holds them away from the data's minimum, or the fit stopped early"
                 if regularized else "the fit stopped before the minimum: run more iterations (or polish steps)")
        out[name] = (float(bad.mean()), f"{name} has not converged in {_percent(bad.mean())} % of the {n} seen texels "
                     f"(a last Gauss-Newton step > {threshold:g} standard errors or at the step limit, the value "
                     f"at a bound, the texel's residuals above the noise: chi-square p < {MISFIT_P:g}, or another "
                     f"parameter of the texel not converged; its largest step there {worst:.3g} standard errors): "
                     f"{cause}; "
                     f"their standard errors are set to NaN (result.converged marks them)")
    return out


def _percent(fraction: float) -> str:
    """A fraction as a percentage: whole per cent from 1 % on, two significant digits below (a few
    texels of a large map must not read as '0 %')."""
    return f"{100 * fraction:.0f}" if fraction >= 0.01 else f"{100 * fraction:.2g}"
