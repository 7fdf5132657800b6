"""Stability map of the NumPy evaluator and the DHR: where it is accurate, where it degrades,
where it refuses.

Sweeps every input to its edges — theta_i, theta_r -> 0 and 90 deg, rms_slope 1e-5 .. 1e3
(accepted: 1e-4 .. 100), k from 0 to 1e7 (accepted: <= 1e6), PEC — and classifies each point:

- accurate:  finite, and within 1e-9 (relative to the matrix's largest element) of an
             independent vector-form derivation of Eqs. 6-13 (facet frames from cross products),
- degrades:  finite but further from the reference (reported with its error),
- refuses:   a ValueError naming the parameter (outside the accepted range),
- fails:     anything else (NaN, Inf, another exception) -- must never happen.

Writes stability_evaluator.png (one panel per sweep) and stability_evaluator.csv.
"""
import math
from pathlib import Path

import numpy as np


import hyde_bsdf
from hyde_bsdf.model.jones_mueller import jones_to_mueller

from hyde_bsdf.validation._common import CLASSES, cli, stability_chart, write_csv  # noqa: E402



def vector_reference(ti, tr, ph, s, n, k, pec):
    """Eq. 6/13 from vectors (independent of the angle formulas); None where it is undefined."""
    wi = np.array([math.sin(ti), 0.0, math.cos(ti)])
    wr = np.array([math.sin(tr) * math.cos(ph), math.sin(tr) * math.sin(ph), math.cos(tr)])
    if wi[2] <= 1e-15 or wr[2] <= 1e-15:     # at or below the horizon (90 deg: cos(pi/2) = 6e-17 is rounding)
        return np.zeros((4, 4))
    z = np.array([0.0, 0.0, 1.0])
    h = wi + wr
    if np.linalg.norm(np.cross(-wi, z)) < 1e-12 or np.linalg.norm(np.cross(wr, z)) < 1e-12 \
            or np.linalg.norm(np.cross(-wi, h / np.linalg.norm(h))) < 1e-12:
        return None                       # frames undefined exactly at the poles / backscatter
    h /= np.linalg.norm(h)

    def basis(kv):
        sv = np.cross(kv, z)
        sv /= np.linalg.norm(sv)
        return sv, np.cross(kv, sv)

    (si, pi), (sr, pr) = basis(-wi), basis(wr)
    sf = np.cross(-wi, h)
    sf /= np.linalg.norm(sf)
    pfi, pfr = np.cross(-wi, sf), np.cross(wr, sf)
    cb = wi @ h
    if pec:
        rs, rp = -1.0, 1.0
    else:
        eta2 = complex(n, k) ** 2
        w = np.sqrt(eta2 - (1 - cb * cb))
        rs, rp = np.conj((cb - w) / (cb + w)), np.conj((eta2 * cb - w) / (eta2 * cb + w))
    T = (np.array([[sr @ sf, sr @ pfr], [pr @ sf, pr @ pfr]]) @ np.diag([rs, rp])
         @ np.array([[si @ sf, pi @ sf], [si @ pfi, pi @ pfi]]))
    ca = h[2]
    tan2 = (h[0] ** 2 + h[1] ** 2) / ca ** 2
    D = math.exp(-tan2 / (2 * s * s)) / (2 * math.pi * s * s * ca ** 4)
    G = min(1.0, 2 * ca * wr[2] / cb, 2 * ca * wi[2] / cb)
    return D * G / (4 * wi[2] * wr[2]) * jones_to_mueller(T)


def classify(ti, tr, ph, s, n=None, k=0.0, pec=False):
    kw = dict(pec=True) if pec else dict(n=n, k=k)
    try:
        F = hyde_bsdf.pbrdf(ti, tr, ph, rms_slope=s, diffuse=False, **kw)
    except ValueError as exc:
        return "refuses", float("nan"), str(exc)
    except Exception as exc:              # noqa: BLE001 -- this is what the map looks for
        return "fails", float("nan"), repr(exc)
    if not np.all(np.isfinite(F)):
        return "fails", float("nan"), "non-finite"
    ref = vector_reference(ti, tr, ph, s, n, k, pec)
    if ref is None:                       # frames undefined: compare with the reference 1e-6 away
        ref = vector_reference(ti + 1e-6, tr + 2e-6, ph + 1e-6, s, n, k, pec)
        tol = 1e-4                        # continuity to the limit, O(1e-6) slopes
    else:
        tol = 1e-9
    scale = max(np.abs(ref).max(), np.abs(F).max(), 1e-300)
    err = float(np.abs(F - ref).max() / scale)
    return ("accurate" if err <= tol else "degrades"), err, ""


def sweeps(quick):
    m = 25 if quick else 61
    deg = np.concatenate([[0.0, 1e-6, 1e-3], np.linspace(0.5, 89.5, m - 8), [89.9, 89.999, 90 - 1e-6, 90.0, 95.0]])
    slopes = np.logspace(-5, 3, m)
    ks = np.concatenate([[0.0], np.logspace(-3, 7, m - 1)])
    yield ("theta_i (deg), theta_r = 30 deg, phi = 2", "theta_i", deg,
           lambda v: classify(math.radians(v), math.radians(30), 2.0, 0.3, 0.285, 7.35))
    yield ("theta_r (deg), theta_i = 60 deg, phi = pi", "theta_r", deg,
           lambda v: classify(math.radians(60), math.radians(v), math.pi, 0.3, 0.285, 7.35))
    yield ("backscatter theta_i = theta_r (deg), phi = 1e-9", "theta", deg,
           lambda v: classify(math.radians(v), math.radians(v), 1e-9, 0.3, 1.5, 0.0))
    yield ("rms_slope (log), 40 deg -> 50 deg, phi = 3", "rms_slope", slopes,
           lambda v: classify(math.radians(40), math.radians(50), 3.0, v, 0.285, 7.35))
    yield ("k (log; 0 first), n = 1.5, 40 -> 50 deg", "k", ks,
           lambda v: classify(math.radians(40), math.radians(50), 3.0, 0.3, 1.5, v))
    yield ("PEC, theta_i (deg), theta_r = 45, phi = 1", "theta_i_pec", deg,
           lambda v: classify(math.radians(v), math.radians(45), 1.0, 0.3, pec=True))


def validate(outdir="out/validation", quick=False):
    out = Path(outdir)
    out.mkdir(parents=True, exist_ok=True)
    rows, panels = [], []
    for title, name, values, fn in sweeps(quick):
        res = [fn(v) for v in values]
        panels.append((title, values, res))
        rows += [[name, v, c, e, msg] for v, (c, e, msg) in zip(values, res)]
    stability_chart(panels, out / "stability_evaluator.png",
                    "Evaluator stability map (bars: class; dots: error vs vector derivation)")
    write_csv(out / "stability_evaluator.csv", ["sweep", "value", "class", "rel_error_vs_vector_form", "message"], rows)
    counts = {c: sum(r[2] == c for r in rows) for c in CLASSES}
    refusals_named = all(any(p in r[4] for p in ("rms_slope", "theta", "k", "n")) for r in rows if r[2] == "refuses")
    return [dict(name="Evaluator stability map: points that fail (NaN/Inf/crash)", value=counts["fails"],
                 tolerance=0, passed=counts["fails"] == 0),
            dict(name="Evaluator stability map: points that degrade (> 1e-9 from the vector form)",
                 value=counts["degrades"], tolerance=0, passed=counts["degrades"] == 0),
            dict(name="Evaluator stability map: refusals name the parameter", value=counts["refuses"],
                 tolerance="all named", passed=refusals_named)]


if __name__ == "__main__":
    cli(validate, __doc__)
