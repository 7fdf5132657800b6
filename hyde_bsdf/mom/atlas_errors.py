"""The atlas's numbers: every model variant against the MoM checkpoints, per Mueller element and region.

What is compared
----------------
For each checkpoint of :mod:`hyde_bsdf.mom.atlas` (one surface, one material, both polarisations, the
partitions' far fields) and each incidence angle, the MoM's *incoherent* in-plane Mueller elements --
the partitions' mean minus the coherent part (M |<F>|^2 - <|F|^2>) / (M - 1), the mirror reflection that
a finite illuminated length turns into a spike of width lambda / w and that the model, a BRDF, does not
have (its share of the reflected power is kept apart: ``coherent``) -- against every model variant of the
registry (:func:`variants`: shadowing x diffuse, reduced to the 1-D surface by
:func:`hyde_bsdf.mom.model1d.mueller_sigma`, in the same sigma units).  Both curves are smoothed over
+-1 deg (the MoM's speckle is ~0.8 deg wide at w = 75 lambda) on the 0.5 deg grid.

Elements (:data:`ELEMENTS`): M00 in dB, 10 log10(model / MoM); M01/M00, M22/M00, M23/M00 and M11/M00 as
differences model - MoM of the normalised elements (on a 1-D surface in the plane of incidence the MoM's
M11/M00 is exactly 1; the model's is below 1 by its unpolarised diffuse share; M10 = M01, M33 = M22,
M32 = -M23 and the other eight elements are 0 in both).

Regions (:data:`REGIONS`), from the MoM's smoothed incoherent M00, over the angles where the MoM is clear
of its partition floor (``valid``) and |theta_r| <= 88 deg: ``lobe``, the rms of the difference weighted by
the MoM's M00 (relative to its peak, wherever that is >= 1 %: the light that is there counts, and no angle
near a threshold flips in or out with the speckle), ``specular`` within 2.5 deg of theta_r = theta_i (the
mean difference, signed), and ``wing`` where M00 is 1-10 % of its peak (rms).  For an observation angle,
the lobe is where M00 >= 10 % of its peak.

Statistical error: a jackknife over partitions (leave one out; the coherent part and the regions are
re-estimated in each replicate, so their speckle counts too; with only 2 partitions the coherent part is
held at its full estimate).  The rms is taken of the jackknife's bias-corrected mean square, which removes the speckle's
own O(1/M) contribution to it, so an exact model reads near 0 rather than at the speckle's size.  ``se``
is the jackknife standard error of the stated error.  A cell is ``not_converged`` where reflected +
absorbed power is off 1 by more than :data:`ENERGY_LIMIT` in either polarisation, ``too_costly`` where
the MoM run was not affordable, ``no_signal`` where no angle stands clear of the floor.
"""
from __future__ import annotations

import datetime as _dt
import json
import math
import platform
import time
from pathlib import Path

import numpy as np

from hyde_bsdf.io.atomic import atomic_path
from hyde_bsdf.mom.atlas import Grid, load_checkpoints

__all__ = ["ELEMENTS", "REGIONS", "STATUS", "variants", "mom_elements", "model_elements", "cell_errors",
           "variant_costs", "build_table", "write_table", "ENERGY_LIMIT"]

ELEMENTS = ("M00_dB", "M01", "M11", "M22", "M23")
REGIONS = ("lobe", "specular", "wing")
STATUS = ("ok", "too_costly", "not_converged", "no_signal", "not_run")
#: lobe and wing levels relative to the MoM's peak M00; half-width of the specular window; of the smoothing
LOBE_LEVEL, WING_LEVEL, SPECULAR_HALF_DEG, SMOOTH_HALF_DEG, GRAZING_DEG = 0.1, 0.01, 2.5, 2.5, 88.0
#: |reflected + absorbed - 1| beyond this (either polarisation) marks the MoM not converged at that angle: 5 % of the
#: power is 0.2 dB of M00, a fifth of the default tolerance (large heights at 50-85 deg reach it: the windowed
#: current's bias on a surface of sigma_h = 2-4 lambda, the beam's footprint moved by sigma_h tan theta_i)
ENERGY_LIMIT = 0.05


def variants():
    """(shadowing, diffuse) pairs of the model's registry (:mod:`hyde_bsdf.model.terms`) that make a model
    (:func:`~hyde_bsdf.model.terms.allowed`) and have no parameters of their own: a term added there joins the
    atlas when the table is rebuilt (a term with its own parameters -- a free Lambertian albedo -- has no one
    value to grade, and is left out)."""
    from hyde_bsdf.model.terms import DIFFUSE_TERMS, SHADOWING_TERMS, allowed

    return [(s.name, d.name) for s in SHADOWING_TERMS for d in DIFFUSE_TERMS
            if allowed(s.name, d.name) and not d.parameters]


def _smooth(a, steps):
    """Moving average over 2 steps + 1 samples along the last axis (fewer at the ends)."""
    if steps <= 0:
        return a
    kernel = np.ones(2 * steps + 1)
    num = np.apply_along_axis(lambda v: np.convolve(v, kernel, mode="same"), -1, a)
    count = np.convolve(np.ones(a.shape[-1]), kernel, mode="same")
    return num / count


def _coherent(F, G, M):
    """Unbiased coherent part of <F conj(G)> over M partitions: (M <F> conj(<G>) - <F conj(G)>) / (M - 1)."""
    return (M * F.mean(0) * np.conj(G.mean(0)) - (F * np.conj(G)).mean(0)) / (M - 1)


def mom_elements(F_s, F_p, steps, coherent=None):
    """Smoothed incoherent in-plane Mueller elements [n_ti, n_tr] of the partitions' far fields (sigma units).

    ``coherent``: the coherent (ss, pp, sp) parts to subtract (default: estimated from these partitions).
    Returns (elements dict M00, M01, M22, M23; the coherent parts used).
    """
    M = F_s.shape[0]
    if coherent is None:
        coherent = tuple(_coherent(a, b, M) for a, b in ((F_s, F_s), (F_p, F_p), (F_s, F_p)))
    ss = (np.abs(F_s) ** 2).mean(0) - coherent[0].real
    pp = (np.abs(F_p) ** 2).mean(0) - coherent[1].real
    sp = (F_s * np.conj(F_p)).mean(0) - coherent[2]
    raw = {"M00": 0.5 * (ss + pp), "M01": 0.5 * (ss - pp), "M22": sp.real, "M23": sp.imag}
    return {k: _smooth(v, steps) for k, v in raw.items()}, coherent


def model_elements(theta_i_deg, theta_r_deg, rms_slope, n, k, shadowing, diffuse, steps):
    """The 1-D model's in-plane elements [n_ti, n_tr] (sigma units, smoothed like the MoM's); M11 is its M00
    without the diffuse term (which only M00 carries)."""
    from hyde_bsdf.mom.model1d import mueller_sigma

    ti = np.radians(np.asarray(theta_i_deg, float))[:, None]
    tr = np.radians(np.asarray(theta_r_deg, float))
    kk = None if n is None else k
    m = mueller_sigma(ti, tr, rms_slope, n, 0.0 if kk is None else kk, shadowing, diffuse)
    m["M11"] = mueller_sigma(ti, tr, rms_slope, n, 0.0 if kk is None else kk, shadowing, "none")["M00"]
    return {key: _smooth(np.broadcast_to(v, (ti.size, tr.size)), steps) for key, v in m.items()}


def _differences(model, mom):
    """{element: model - MoM} [n_ti, n_tr]: M00 in dB, the others as normalised elements (NaN where M00 <= 0)."""
    with np.errstate(divide="ignore", invalid="ignore"):
        ok = (mom["M00"] > 0) & (model["M00"] > 0)
        out = {"M00_dB": np.where(ok, 10.0 * np.log10(model["M00"] / mom["M00"]), np.nan),
               "M11": np.where(ok, model["M11"] / model["M00"] - 1.0, np.nan)}
        for key in ("M01", "M22", "M23"):
            out[key] = np.where(ok, model[key] / model["M00"] - mom[key] / mom["M00"], np.nan)
    return out


def _regions(mom_m00, valid, theta_i_deg, theta_r_deg):
    """Weights [n_ti, n_tr] of the three regions; the lobe's and the lobe + wing's theta_r bounds [n_ti, 2] (deg).

    The lobe is weighted by the MoM's M00 / its peak wherever that is >= WING_LEVEL (a power-weighted rms: an
    angle near the 10 % level, which the speckle would put in or out of a hard mask from one replicate to the
    next, counts a tenth either way); the specular window and the wing weigh their angles equally.  The bounds
    (where M00 >= LOBE_LEVEL, resp. WING_LEVEL) say which region an observation angle falls in."""
    tr = np.asarray(theta_r_deg)[None, :]
    usable = valid & (np.abs(tr) <= GRAZING_DEG) & (mom_m00 > 0)
    peak = np.max(np.where(usable, mom_m00, 0.0), axis=1, keepdims=True)
    with np.errstate(invalid="ignore", divide="ignore"):
        rel = np.where(usable, mom_m00 / peak, 0.0)
    lobe = rel >= LOBE_LEVEL
    wing = (rel >= WING_LEVEL) & ~lobe
    spec = usable & (np.abs(tr - np.asarray(theta_i_deg)[:, None]) <= SPECULAR_HALF_DEG)

    def bounds(mask):
        lo = np.where(mask.any(1), np.min(np.where(mask, tr, np.inf), 1), np.nan)
        return np.stack([lo, np.where(mask.any(1), np.max(np.where(mask, tr, -np.inf), 1), np.nan)], 1)

    weights = {"lobe": np.where(rel >= WING_LEVEL, rel, 0.0), "specular": spec.astype(float),
               "wing": wing.astype(float)}
    return weights, bounds(lobe), bounds(lobe | wing)


def _weighted(diffs, weights, square):
    """[n_el, n_reg, n_ti]: the weighted mean of d^2 (``square``; the specular window's of d) over each region."""
    out = np.full((len(ELEMENTS), len(REGIONS), next(iter(weights.values())).shape[0]), np.nan)
    for e, el in enumerate(ELEMENTS):
        d = diffs[el]
        for r, reg in enumerate(REGIONS):
            w = np.where(np.isfinite(d), weights[reg], 0.0)
            total = w.sum(1)
            f = d * d if (square and reg != "specular") else d
            val = np.where(w > 0, f * w, 0.0).sum(1)
            out[e, r] = np.where(total > 0, val / np.where(total > 0, total, 1.0), np.nan)
    return out


def _moments(diffs, weights):
    """[n_el, n_reg, n_ti] of the region statistic: mean square (lobe, wing) or mean (specular)."""
    return _weighted(diffs, weights, True)


def _jackknife(full, parts):
    """Bias-corrected estimate and standard error of a statistic from its value and leave-one-out values."""
    M = parts.shape[0]
    mean = parts.mean(0)
    return M * full - (M - 1) * mean, np.sqrt((M - 1) / M * ((parts - mean) ** 2).sum(0))


def _status(ck, n_ti, masks):
    status = np.zeros(n_ti, np.int8)
    if ck["status"] != "ok":
        return np.full(n_ti, STATUS.index("too_costly"), np.int8), np.full(n_ti, np.nan)
    energy_error = np.max(np.abs(ck["energy"] - 1.0), axis=0)
    status[energy_error > ENERGY_LIMIT] = STATUS.index("not_converged")
    status[(status == 0) & ~(masks["lobe"] > 0).any(1)] = STATUS.index("no_signal")
    return status, energy_error


def cell_errors(ck, var=None):
    """Errors of every variant at every incidence angle of one checkpoint.

    Returns a dict: ``error``, ``signed``, ``se`` [n_ti, n_var, n_el, n_reg] (NaN where unknown), ``status``
    [n_ti] (index into :data:`STATUS`), ``coherent`` and ``energy_error`` [n_ti], ``lobe_deg`` and
    ``wing_deg`` [n_ti, 2] (the regions' theta_r bounds).
    """
    task = json.loads(ck["task"])
    var = variants() if var is None else var
    ti, n_ti = task["theta_i_deg"], len(task["theta_i_deg"])
    shape = (n_ti, len(var), len(ELEMENTS), len(REGIONS))
    out = {key: np.full(shape, np.nan) for key in ("error", "signed", "se")}
    if ck["status"] != "ok":
        status, energy = _status(ck, n_ti, None)
        return dict(out, status=status, coherent=np.full(n_ti, np.nan), energy_error=energy,
                    lobe_deg=np.full((n_ti, 2), np.nan), wing_deg=np.full((n_ti, 2), np.nan))
    tr = Grid(theta_r_step_deg=task["theta_r_step_deg"]).theta_r_deg()
    steps = int(round(SMOOTH_HALF_DEG / task["theta_r_step_deg"]))
    F_s, F_p = ck["F_s"].astype(complex), ck["F_p"].astype(complex)
    M = F_s.shape[0]
    mom, coh = mom_elements(F_s, F_p, steps)
    masks, lobe, wing = _regions(mom["M00"], ck["valid"], ti, tr)
    status, energy = _status(ck, n_ti, masks)
    # leave-one-out replicates: the coherent part (where 2 partitions remain) and the regions re-estimated in
    # each, so that their speckle is in the standard error too
    loo = []
    for i in range(M):
        m, _ = mom_elements(np.delete(F_s, i, 0), np.delete(F_p, i, 0), steps, coh if M < 3 else None)
        loo.append((m, _regions(m["M00"], ck["valid"], ti, tr)[0]))
    for v, (sh, df) in enumerate(var):
        model = model_elements(ti, tr, task["rms_slope"], task["n"], task["k"], sh, df, steps)
        full = _moments(_differences(model, mom), masks)
        parts = np.stack([_moments(_differences(model, m), mk) for m, mk in loo])
        est, se = _jackknife(full, parts)
        err, sgn, err_se = _finish(est, se, _moments_mean(_differences(model, mom), masks))
        ok = (status == 0)[None, None, :]
        for key, val in (("error", err), ("signed", sgn), ("se", err_se)):
            out[key][:, v] = np.where(ok, val, np.nan).transpose(2, 0, 1)
    return dict(out, status=status, coherent=np.asarray(ck["coherent"], float), energy_error=energy,
                lobe_deg=lobe, wing_deg=wing)


def _moments_mean(diffs, weights):
    """[n_el, n_reg, n_ti] mean difference over each region (the signed error)."""
    return _weighted(diffs, weights, False)


def _finish(est, se, mean):
    """(error, signed, se of the error) from the jackknifed statistics: sqrt of the mean square (lobe, wing),
    |mean| (specular)."""
    spec = REGIONS.index("specular")
    err, err_se, sgn = np.empty_like(est), np.empty_like(se), mean.copy()
    rms = np.sqrt(np.maximum(est, 0.0))
    rms_se = se / (2.0 * np.sqrt(np.maximum(est, np.maximum(se, 1e-30))))
    err[:], err_se[:] = rms, rms_se
    err[:, spec], err_se[:, spec], sgn[:, spec] = np.abs(est[:, spec]), se[:, spec], est[:, spec]
    return err, sgn, err_se


def variant_costs(var=None, n=20000, rounds=7):
    """Seconds per evaluation of each variant's 3-D evaluator (:func:`hyde_bsdf.model.pbrdf`, a finite index,
    ``n`` random direction pairs, the fastest of ``rounds``: the least disturbed by other work on the machine;
    the DHR table loaded before timing)."""
    from hyde_bsdf.model.evaluator import pbrdf

    var = variants() if var is None else var
    rng = np.random.default_rng(0)
    ti, tr, ph = rng.uniform(0, 1.4, n), rng.uniform(0, 1.4, n), rng.uniform(0, 2 * math.pi, n)
    out = []
    for sh, df in var:
        pbrdf(ti[:10], tr[:10], ph[:10], rms_slope=0.3, n=1.5, k=3.0, shadowing=sh, diffuse=df)
        times = []
        for _ in range(rounds):
            t0 = time.perf_counter()
            pbrdf(ti, tr, ph, rms_slope=0.3, n=1.5, k=3.0, shadowing=sh, diffuse=df)
            times.append(time.perf_counter() - t0)
        out.append(float(np.min(times)) / n)
    return np.array(out)


def _axes(checkpoints):
    """The table's axes from the checkpoints' tasks: slopes, heights, materials (n, k), incidence angles."""
    tasks = [json.loads(ck["task"]) for ck in checkpoints.values()]
    slopes = sorted({t["rms_slope"] for t in tasks})
    heights = sorted({t["height_wl"] for t in tasks})
    mats = {}
    for t in tasks:
        mats.setdefault(t["material"], (t["n"], t["k"]))
    ti = tasks[0]["theta_i_deg"]
    return slopes, heights, mats, ti, tasks


def build_table(checkpoints, var=None):
    """The atlas as a dict of arrays (what :func:`write_table` stores; :mod:`hyde_bsdf.model.accuracy` reads)."""
    from hyde_bsdf.mom.atlas import MATERIALS

    var = variants() if var is None else var
    slopes, heights, mats, ti, tasks = _axes(checkpoints)
    names = [m for m in MATERIALS if m in mats] + sorted(m for m in mats if m not in MATERIALS)
    cell = (len(names), len(slopes), len(heights), len(ti))
    full = cell + (len(var), len(ELEMENTS), len(REGIONS))
    tab = {key: np.full(full, np.nan, np.float32) for key in ("error", "signed", "se")}
    tab.update(status=np.full(cell, STATUS.index("not_run"), np.int8),
               **{key: np.full(cell, np.nan, np.float32) for key in ("coherent", "energy_error")},
               **{key: np.full(cell + (2,), np.nan, np.float32) for key in ("lobe_deg", "wing_deg")},
               **{key: np.zeros(cell[:3], np.float64) for key in ("cpu_s", "partitions", "seed", "unknowns",
                                                                   "corr_length_wl", "partition_wl", "pts_per_wl")})
    for ck, task in zip(checkpoints.values(), tasks):
        at = (names.index(task["material"]), slopes.index(task["rms_slope"]), heights.index(task["height_wl"]))
        res = cell_errors(ck, var)
        for key in ("error", "signed", "se", "status", "coherent", "energy_error", "lobe_deg", "wing_deg"):
            tab[key][at] = res[key]
        for key, val in (("cpu_s", ck["cpu_s"]), ("partitions", ck["partitions"]), ("seed", task["seed"]),
                         ("unknowns", ck["unknowns"]), ("corr_length_wl", task["corr_length_wl"]),
                         ("partition_wl", task["partition_wl"]), ("pts_per_wl", ck["pts_per_wl_used"])):
            tab[key][at] = float(val)
    tab.update(materials=np.array(names), material_n=np.array([np.nan if mats[m][0] is None else mats[m][0]
                                                               for m in names]),
               material_k=np.array([np.nan if mats[m][1] is None else mats[m][1] for m in names]),
               rms_slopes=np.array(slopes), heights_wl=np.array(heights), theta_i_deg=np.array(ti, float),
               variants=np.array([f"{sh}/{df}" for sh, df in var]), elements=np.array(ELEMENTS),
               regions=np.array(REGIONS), status_names=np.array(STATUS), variant_cost_s=variant_costs(var))
    tab["provenance"] = np.array(json.dumps(_provenance(tasks, checkpoints, tab)))
    return tab


def _provenance(tasks, checkpoints, tab):
    """What made the table: versions, grid, MoM settings, seeds and partitions per run, the statistics' rules."""
    from hyde_bsdf import __version__
    from hyde_bsdf.mom.atlas import ELLS_PER_PARTITION, MIN_PARTITIONS, PARTITION_WL, PARTITIONS, TASK_CPU_CAP_S
    from hyde_bsdf.mom.fast import FAST_TOL

    t = tasks[0]
    return {
        "format": 1, "package_version": __version__, "created_utc": _dt.datetime.now(_dt.timezone.utc).isoformat(
            timespec="seconds"), "machine": f"{platform.machine()} {platform.processor()}".strip(),
        "domain": "1-D Gaussian rough surfaces (Gaussian correlation), in-plane scattering; 2-D surfaces: see "
                  "docs/accuracy.md",
        "grid": {"theta_i_deg": t["theta_i_deg"], "theta_r_step_deg": t["theta_r_step_deg"],
                 "rms_slopes": tab["rms_slopes"].tolist(), "heights_wl": tab["heights_wl"].tolist()},
        "materials": {str(m): [None if math.isnan(n) else n, None if math.isnan(k) else k] for m, n, k in
                      zip(tab["materials"], tab["material_n"], tab["material_k"])},
        "mom": {"polarization": "s and p on the same surface", "incidence": "auto (beam from 80 deg)",
                "taper": "w = partition / 4", "partition_wl": f"max({PARTITION_WL:g}, {ELLS_PER_PARTITION:g} ell)",
                "pts_per_wl": "10 (15 from rms slope 0.5), >= 6 / ell, resampled by the solver where steep",
                "fast_solver_tol": FAST_TOL, "partitions": f"{PARTITIONS} (>= {MIN_PARTITIONS} where a run would "
                f"exceed {TASK_CPU_CAP_S:g} CPU s)", "seeds": "pilot partition seed, the others seed + 1",
                "runs": {k: {"seed": json.loads(c["task"])["seed"], "partitions": int(c["partitions"]),
                             "cpu_s": round(float(c["cpu_s"]), 1), "status": str(c["status"])}
                         for k, c in checkpoints.items()},
                "cpu_s_total": round(float(sum(float(c["cpu_s"]) for c in checkpoints.values())), 1)},
        "statistics": {"compared": "MoM incoherent elements against the 1-D model (mom.model1d), both smoothed over "
                                   f"+-{SMOOTH_HALF_DEG:g} deg", "lobe_level": LOBE_LEVEL, "wing_level": WING_LEVEL,
                       "specular_half_deg": SPECULAR_HALF_DEG, "grazing_deg": GRAZING_DEG,
                       "energy_limit": ENERGY_LIMIT, "errors": "rms over lobe / wing (jackknife bias-corrected mean "
                       "square), |mean| in the specular window; se: jackknife over partitions"},
        "variant_cost": "seconds per evaluation of hyde_bsdf.model.pbrdf (3-D), fastest of 7 x 20000 pairs",
    }


def write_table(folder, path):
    """Build the table from the checkpoints in ``folder`` and write it (compressed npz, atomically)."""
    tab = build_table(load_checkpoints(folder))
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    with atomic_path(path) as tmp:
        with open(tmp, "wb") as fh:
            np.savez_compressed(fh, **tab)
    return path
