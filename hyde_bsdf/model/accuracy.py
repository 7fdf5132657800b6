"""Where the model holds: the accuracy atlas's verdict for a geometry, roughness, height and index (issue 32).

The atlas (``hyde_bsdf/data/accuracy_atlas.npz``, made by ``hyde_bsdf/validation/accuracy_atlas.py`` (``run``, ``table``) from
:mod:`hyde_bsdf.mom.atlas` runs) holds, for 1-D Gaussian rough surfaces, the error of every model
variant (shadowing x diffuse) against the exact MoM, per Mueller element and region of theta_r, with the
MoM's own standard error; this module reads it with NumPy alone and answers :func:`accuracy`.

How an answer is made
---------------------
* Range: incidence 0-85 deg, rms slope 0.05-0.7, sigma_h / lambda 0.1-4 (the atlas's); outside, and
  where the MoM was too costly or did not converge, the answer is "unknown" with the reason.
* Between grid nodes of incidence, slope and height the stated error is the *largest* of the
  surrounding nodes' (a bound, not an interpolation: the error can change fast, near grazing most).
* The index: a perfect conductor is the atlas's PEC; a conductor (k >= n and k >= 1) between two
  atlas conductors along 1 / |eta| (PEC 0, Al 1550 nm, Al 633 nm, Au 633 nm) is interpolated linearly
  where the two materials' errors agree within max(tolerance / 2, 2 combined standard errors) --
  "smooth" -- and takes the larger otherwise; a dielectric with 1.3 <= n <= 1.8 and k <= 0.05 n is the
  atlas's glass (n = 1.5); anything else is "unknown" (the nearest material is named).
* Verdict per element: ``valid`` True where error + 2 se <= tolerance (within it at two MoM standard
  errors), False where the error exceeds the tolerance, None between (within it by the estimate, but
  the MoM's statistical error leaves it open).
* Without ``sigma_h_wl`` the answer covers every atlas height: ``error`` is the largest,
  ``error_range`` [smallest, largest], ``valid`` True only if valid at every height.
* ``recommended``: the cheapest variant (seconds per evaluation of :func:`hyde_bsdf.model.pbrdf`) valid
  in every graded element; none where no variant is -- then use the MoM (its cost at the nearest cell
  is given) or, for a slightly rough surface (k sigma_h cos theta_i < 0.3), perturbation theory.

Elements: ``M00_dB`` (10 log10 model / exact), the normalised ``M01``, ``M11``, ``M22``, ``M23``
(model - exact of Mij / M00) are graded by the atlas; on a 1-D surface in the plane of incidence
``M10`` = M01, ``M33`` = M22, ``M32`` = -M23 and the other eight vanish in both, so they carry the
same verdicts ("source" says which).  A 2-D surface adds out-of-plane tilts: docs/accuracy.md says
what the 1-D atlas implies there.
"""
from __future__ import annotations

import json
import math
from functools import lru_cache
from pathlib import Path

import numpy as np

from hyde_bsdf.errors import UsageError, shorten
from hyde_bsdf.io.arrays import read_npz
from hyde_bsdf.io.input_gate import check_input

__all__ = ["accuracy", "verdict", "load_atlas", "Atlas", "ATLAS_PATH", "TOLERANCE_DB", "TOLERANCE", "ELEMENTS_16"]

#: the shipped table
ATLAS_PATH = Path(__file__).resolve().parent.parent / "data" / "accuracy_atlas.npz"
#: default tolerances: M00 in dB, the normalised elements in absolute units
TOLERANCE_DB = 1.0
TOLERANCE = 0.1
#: every element of the 4 x 4 matrix: (name, atlas element it follows or None for 0 in both, sign)
ELEMENTS_16 = (("M00_dB", "M00_dB"), ("M01", "M01"), ("M02", None), ("M03", None),
               ("M10", "M01"), ("M11", "M11"), ("M12", None), ("M13", None),
               ("M20", None), ("M21", None), ("M22", "M22"), ("M23", "M23"),
               ("M30", None), ("M31", None), ("M32", "M23"), ("M33", "M22"))
#: index families: conductors along 1/|eta|, dielectrics near the atlas's glass
_GLASS_N, _GLASS_K_OVER_N = (1.3, 1.8), 0.05
_SLIGHT_ROUGHNESS = 0.3


class Atlas:
    """The atlas's arrays (:mod:`hyde_bsdf.mom.atlas_errors` documents each) and its provenance."""

    def __init__(self, path):
        path = Path(check_input(path, "accuracy atlas", stdin=False))     # a regular file: no FIFO, no device
        try:
            self.arrays = read_npz(path, "accuracy atlas")       # sized from its members' headers first
        except UsageError as exc:
            raise UsageError(f"{exc}; rebuild it with python hyde_bsdf/validation/accuracy_atlas.py table") from None
        a = self.arrays
        self.path = path
        try:
            self.provenance = json.loads(str(a["provenance"]))
            self.materials = [str(m) for m in a["materials"]]
            self.variants = [tuple(str(v).split("/")) for v in a["variants"]]
            self.elements = [str(e) for e in a["elements"]]
            self.regions = [str(r) for r in a["regions"]]
            self.status_names = [str(s) for s in a["status_names"]]
            self.theta_i = a["theta_i_deg"].astype(float)
            self.slopes = a["rms_slopes"].astype(float)
            self.heights = a["heights_wl"].astype(float)
        except KeyError as exc:         # another .npz given as the atlas
            raise UsageError(f"accuracy atlas {shorten(str(path))} has no array {exc}: not an accuracy atlas; rebuild "
                             "it with python hyde_bsdf/validation/accuracy_atlas.py table") from None

    def __getitem__(self, key):
        return self.arrays[key]


@lru_cache(maxsize=4)
def load_atlas(path=None) -> Atlas:
    """The atlas at ``path`` (default the shipped table), read once per process."""
    return Atlas(ATLAS_PATH if path is None else path)


def _bracket(nodes, x, name, unit):
    """Indices of the grid nodes around ``x`` (one if on a node); None outside the grid."""
    if x < nodes[0] - 1e-9 or x > nodes[-1] + 1e-9:
        return None
    hit = np.flatnonzero(np.abs(nodes - x) <= 1e-9 * max(1.0, abs(x)))
    if hit.size:
        return [int(hit[0])]
    i = int(np.searchsorted(nodes, x))
    return [i - 1, i]


def _material_weights(atlas, n, k):
    """[(material index, weight)], the nearest material's name, and the reason where none applies."""
    names = atlas.materials
    if n is None:
        return [(names.index("PEC"), 1.0)], "PEC", None
    mn, mk = atlas["material_n"], atlas["material_k"]
    if k <= _GLASS_K_OVER_N * n:
        glass = [i for i, m in enumerate(names) if not math.isnan(mk[i]) and mk[i] <= _GLASS_K_OVER_N * mn[i]]
        if glass and _GLASS_N[0] <= n <= _GLASS_N[1]:
            return [(glass[0], 1.0)], names[glass[0]], None
        return [], names[glass[0]] if glass else "glass", (
            f"a dielectric of n = {n:g} is outside the atlas's glass family (n {_GLASS_N[0]:g}-{_GLASS_N[1]:g})")
    conductors = sorted((0.0 if math.isnan(mn[i]) else 1.0 / math.hypot(mn[i], mk[i]), i)
                        for i in range(len(names)) if math.isnan(mn[i]) or mk[i] >= max(mn[i], 1.0))
    u = 1.0 / math.hypot(n, k)
    us = np.array([c[0] for c in conductors])
    nearest = names[conductors[int(np.argmin(np.abs(us - u)))][1]]
    if not (k >= max(n, 1.0)) or u > us[-1] * (1.0 + 1e-9):
        edge = f", |eta| >= {1.0 / us[-1]:.3g}" if us[-1] > 0 else ""
        return [], nearest, (f"n = {n:g}, k = {k:g} lies outside the atlas's conductors (k >= n{edge}) and its "
                             "glass: no atlas material is near enough")
    j = min(int(np.searchsorted(us, u)), len(us) - 1)
    if abs(us[j] - u) <= 1e-12 or j == 0:
        return [(conductors[j][1], 1.0)], nearest, None
    t = (u - us[j - 1]) / (us[j] - us[j - 1])
    return [(conductors[j - 1][1], 1.0 - t), (conductors[j][1], t)], nearest, None


def _region(atlas, at, theta_i_deg, theta_r_deg, specular_half):
    """The atlas region (index) the observation falls in at node ``at`` (material, slope, height, theta_i), with
    theta_r moved with the node's incidence angle; None outside the graded angles."""
    if theta_r_deg is None:
        return atlas.regions.index("lobe")
    offset = theta_r_deg - theta_i_deg
    if abs(offset) <= specular_half:
        return atlas.regions.index("specular")
    tr = atlas.theta_i[at[3]] + offset
    for name, key in (("lobe", "lobe_deg"), ("wing", "wing_deg")):
        lo, hi = atlas[key][at]
        if lo <= tr <= hi:
            return atlas.regions.index(name)
    return None


def _node(atlas, at, variant, region):
    """(error [n_el], se [n_el], why unknown or None) of one variant at one node and region."""
    code = int(atlas["status"][at])
    if code != 0:
        return None, None, _STATUS_TEXT.get(atlas.status_names[code], atlas.status_names[code])
    if region is None:
        return None, None, "theta_r is outside the lobe and its wing (the MoM puts < 1 % of its peak there)"
    err = atlas["error"][at + (variant, slice(None), region)].astype(float)
    se = atlas["se"][at + (variant, slice(None), region)].astype(float)
    if not np.all(np.isfinite(err)):
        return None, None, "the MoM has no valid angle there (below its partition floor)"
    return err, se, None


_STATUS_TEXT = {"too_costly": "the MoM is too costly there (correlation length below ~0.5 lambda on a metal: the "
                              "solver needs 50-100 points per wavelength)",
                "not_converged": "the MoM itself is not converged there (reflected + absorbed power off 1 by more "
                                 "than 5 %)",
                "no_signal": "the MoM has no valid angle there (below its partition floor)",
                "not_run": "the atlas has no run there"}


def _combine_materials(values, weights, tol):
    """Errors of the index from the bracketing materials: linear where smooth, the larger elsewhere."""
    if len(values) == 1:
        return values[0][0], values[0][1], [True] * len(values[0][0])
    (ea, sa), (eb, sb) = values
    wa, wb = weights
    smooth = np.abs(ea - eb) <= np.maximum(tol / 2.0, 2.0 * np.hypot(sa, sb))
    err = np.where(smooth, wa * ea + wb * eb, np.maximum(ea, eb))
    se = np.where(smooth, wa * sa + wb * sb, np.where(ea >= eb, sa, sb))
    return err, se, smooth.tolist()


def _stated(atlas, corners, mats, variant, q):
    """The stated error of one variant over the corners around the query: the largest corner's, after the
    materials' combination; (error, se, smooth flags) or (None, None, reason)."""
    worst_e = worst_s = None
    smooth_all = [True] * len(atlas.elements)
    for c in corners:
        values = []
        for mi, _ in mats:
            at = (mi,) + c
            e, s, why = _node(atlas, at, variant, _region(atlas, at, q["theta_i_deg"], q["theta_r_deg"], q["spec"]))
            if why:
                return None, None, why
            values.append((e, s))
        e, s, smooth = _combine_materials(values, [w for _, w in mats], q["tol"])
        smooth_all = [a and b for a, b in zip(smooth_all, smooth)]
        if worst_e is None:
            worst_e, worst_s = e, s
        else:
            worst_s = np.where(e > worst_e, s, worst_s)
            worst_e = np.maximum(worst_e, e)
    return worst_e, worst_s, smooth_all


def _verdict(err, se, tol):
    """True where err + 2 se is within tol (valid, at two standard errors), False where the error itself exceeds
    it (invalid), None between: within the tolerance by the estimate, not by two standard errors."""
    if err + 2.0 * se <= tol:
        return True
    if err > tol:
        return False
    return None


def _check_query(theta_i, theta_r, rms_slope, n, k, sigma_h_wl, shadowing, diffuse, tol_db, tol):
    """The query's values checked (UsageError naming the parameter); angles back in degrees."""
    from hyde_bsdf.model.terms import diffuse_term, shadowing_term

    def real(name, v, lo=-math.inf, hi=math.inf, lo_open=False):
        try:
            x = float(v)
        except (TypeError, ValueError):
            raise UsageError(f"{name} must be a real number, got {shorten(v)}") from None
        if not (math.isfinite(x) and (x > lo if lo_open else x >= lo) and x <= hi):
            raise UsageError(f"{name} must be finite and in {'(' if lo_open else '['}{lo:g}, {hi:g}], got {shorten(v)}")
        return x

    def degrees(x):                         # the answer's angles in degrees, without the radians' round-off
        return round(math.degrees(x), 9)

    out = dict(theta_i_deg=degrees(real("theta_i", theta_i, 0.0, math.pi / 2)),
               theta_r_deg=None if theta_r is None else degrees(real("theta_r", theta_r, -math.pi / 2, math.pi / 2)),
               rms_slope=real("rms_slope", rms_slope, 0.0, math.inf, True),
               n=None if n is None else real("n", n, 0.0, math.inf, True),
               k=None if n is None and k is None else real("k", 0.0 if k is None else k, 0.0),
               sigma_h_wl=None if sigma_h_wl is None else real("sigma_h_wl", sigma_h_wl, 0.0, math.inf, True),
               shadowing=shadowing_term(shadowing).name, diffuse=diffuse_term(diffuse).name,
               tol_db=real("tol_db", tol_db, 0.0, math.inf, True), tol=real("tol", tol, 0.0, math.inf, True))
    if n is None and k is not None:
        raise UsageError(f"k={shorten(k)} needs n (the index n - jk); give n, or neither for a perfect conductor")
    return out


def _outside(atlas, q):
    """Why the query is outside the atlas's range (None if inside), naming the axis and its range."""
    checks = ((q["theta_i_deg"], atlas.theta_i, "theta_i", "deg"), (q["rms_slope"], atlas.slopes, "rms_slope", ""),
              (q["sigma_h_wl"], atlas.heights, "sigma_h / lambda", ""))
    for value, nodes, name, unit in checks:
        if value is not None and _bracket(nodes, value, name, unit) is None:
            return (f"{name} = {value:.4g}{(' ' + unit) if unit else ''} is outside the atlas "
                    f"({nodes[0]:g}-{nodes[-1]:g}{(' ' + unit) if unit else ''})")
    return None


def _variant_at_height(atlas, q, mats, variant, heights):
    """Per height index: (error, se, smooth) of one variant, or (None, None, reason)."""
    ti = _bracket(atlas.theta_i, q["theta_i_deg"], "", "")
    si = _bracket(atlas.slopes, q["rms_slope"], "", "")
    out = []
    for hset in heights:
        corners = [(s, h, t) for s in si for h in hset for t in ti]
        out.append(_stated(atlas, corners, mats, variant, q))
    return out


def _element_entry(per_height, e, tol):
    """The answer for one graded element from its per-height (error, se) values (None where unknown)."""
    known = [(x[0][e], x[1][e]) for x in per_height if x[0] is not None]
    if len(known) < len(per_height) or not known:
        reason = next(x[2] for x in per_height if x[0] is None)
        return {"error": None, "se": None, "valid": None, "status": "unknown", "reason": reason}
    verdicts = [_verdict(err, se, tol) for err, se in known]
    worst = max(range(len(known)), key=lambda i: known[i][0])
    valid = True if all(v is True for v in verdicts) else False if all(v is False for v in verdicts) else None
    entry = {"error": round(known[worst][0], 4), "se": round(known[worst][1], 4), "valid": valid,
             "tolerance": tol, "status": "valid" if valid else "invalid" if valid is False else "undecided"}
    if len(known) > 1:
        entry["error_range"] = [round(min(k[0] for k in known), 4), round(max(k[0] for k in known), 4)]
        if valid is None:
            entry["reason"] = "depends on the surface height (give sigma_h_wl) or the MoM's statistics leave it open"
    elif valid is None:
        entry["reason"] = "within the tolerance by the estimate, not by 2 MoM standard errors"
    return entry


def _elements(atlas, per_height, q):
    """The 16 elements' entries (the graded five, and the ones the in-plane symmetry ties to them or zeroes)."""
    graded = {}
    for e, name in enumerate(atlas.elements):
        graded[name] = _element_entry(per_height, e, q["tol_db"] if name == "M00_dB" else q["tol"])
    out = {}
    for name, follows in ELEMENTS_16:
        if follows is None:
            out[name] = {"error": 0.0, "se": 0.0, "valid": True, "status": "valid",
                         "source": "0 in both on a 1-D surface in the plane of incidence"}
        else:
            out[name] = dict(graded[follows], source="atlas" if follows == name else f"as {follows} (in-plane symmetry)")
    return out


def _all_valid(per_height, atlas, q):
    """True if every graded element is valid at every height; None if any is undecided or unknown; else False."""
    verdicts = [_element_entry(per_height, e, q["tol_db"] if n == "M00_dB" else q["tol"])["valid"]
                for e, n in enumerate(atlas.elements)]
    return True if all(v is True for v in verdicts) else False if any(v is False for v in verdicts) else None


def _recommend(atlas, q, mats, heights):
    """Every variant's adequacy and cost; the cheapest adequate one (or None, with what to use instead)."""
    costs = atlas["variant_cost_s"]
    rows = []
    for v, (sh, df) in enumerate(atlas.variants):
        ok = _all_valid(_variant_at_height(atlas, q, mats, v, heights), atlas, q)
        rows.append({"shadowing": sh, "diffuse": df, "adequate": ok, "seconds_per_evaluation": float(costs[v])})
    good = sorted((r for r in rows if r["adequate"] is True), key=lambda r: r["seconds_per_evaluation"])
    if good:
        rec = {"method": "model", "shadowing": good[0]["shadowing"], "diffuse": good[0]["diffuse"],
               "seconds_per_evaluation": good[0]["seconds_per_evaluation"]}
    else:
        rec = {"method": "mom", "shadowing": None, "diffuse": None,
               "reason": "no model variant is within the tolerance in every element here"}
    return rec, rows


def _mom_cost(atlas, q, mats, heights):
    """CPU seconds of the atlas's MoM run at the nearest node (all its incidence angles, s and p), and its setup."""
    si = int(np.argmin(np.abs(atlas.slopes - q["rms_slope"])))
    hs = [h for hset in heights for h in hset]
    hi = hs[int(np.argmin([abs(atlas.heights[h] - (q["sigma_h_wl"] or atlas.heights[h])) for h in hs]))]
    mi = mats[0][0] if mats else 0
    at = (mi, si, hi)
    return {"cpu_seconds": round(float(atlas["cpu_s"][at]), 1), "partitions": int(atlas["partitions"][at]),
            "partition_wl": float(atlas["partition_wl"][at]), "pts_per_wl": round(float(atlas["pts_per_wl"][at]), 1),
            "surface": {"rms_slope": float(atlas.slopes[si]), "sigma_h_wl": float(atlas.heights[hi]),
                        "material": atlas.materials[mi]}}


def _coherent(atlas, q, mats, heights):
    """The coherent (mirror) share of the reflected power the model lacks, its largest value around the query."""
    ti = _bracket(atlas.theta_i, q["theta_i_deg"], "", "")
    si = _bracket(atlas.slopes, q["rms_slope"], "", "")
    vals = [float(atlas["coherent"][(m, s, h, t)]) for m, _ in mats for s in si for hset in heights for h in hset
            for t in ti]
    vals = [v for v in vals if math.isfinite(v)]
    if not vals:
        return {"share": None, "valid": None}
    limit = 1.0 - 10.0 ** (-q["tol_db"] / 10.0)      # missing this share of the power is tol_db of M00
    share = max(vals)
    return {"share": round(max(share, 0.0), 4), "valid": share <= limit, "limit": round(limit, 4)}


def accuracy(theta_i, rms_slope, n=None, k=None, *, theta_r=None, sigma_h_wl=None, shadowing="vgroove",
             diffuse="paper", tol_db=TOLERANCE_DB, tol=TOLERANCE, atlas=None):
    """The atlas's verdict on the model at one geometry: per element the expected error of the chosen
    variant and whether it is within the tolerance; the cheapest adequate variant.

    Parameters
    ----------
    theta_i : float, radians in [0, pi/2): incidence angle.
    rms_slope : float > 0, the paper's sqrt(2) sigma_h / ell.
    n, k : the index eta = n - jk (k >= 0); ``n=None`` (and no k) is a perfect conductor.
    theta_r : float or None, radians, signed (+ = the specular side): the observation angle (None: the lobe).
    sigma_h_wl : float or None, the rms surface height in wavelengths (None: every atlas height).
    shadowing, diffuse : the chosen variant (names of the model's registry).
    tol_db, tol : the tolerances of M00 (dB) and of the normalised elements (absolute).
    atlas : an :class:`Atlas` (default the shipped table).

    Returns
    -------
    dict (JSON-able): ``elements`` {name: {"error", "se", "valid", "status", "source", ...}} for all 16
    Mueller elements; ``recommended`` {"method": "model" | "mom", "shadowing", "diffuse", ...};
    ``variants`` (each one's adequacy and cost); ``status`` "ok" or "unknown" and ``reason``; ``region``;
    ``material`` (nearest atlas material, interpolation); ``coherent`` (the mirror share the model lacks);
    ``mom`` (the MoM's cost at the nearest atlas node); ``query``; ``atlas`` (its provenance in short).
    """
    atlas = load_atlas() if atlas is None else atlas
    q = _check_query(theta_i, theta_r, rms_slope, n, k, sigma_h_wl, shadowing, diffuse, tol_db, tol)
    q["spec"] = float(atlas.provenance["statistics"]["specular_half_deg"])
    result = {"query": {key: q[key] for key in ("theta_i_deg", "theta_r_deg", "rms_slope", "n", "k", "sigma_h_wl")},
              "tolerance": {"M00_dB": q["tol_db"], "normalised": q["tol"]},
              "variant": {"shadowing": q["shadowing"], "diffuse": q["diffuse"]},
              "atlas": {"path": str(atlas.path), "package_version": atlas.provenance.get("package_version"),
                        "domain": atlas.provenance.get("domain"), "created_utc": atlas.provenance.get("created_utc")}}
    mats, nearest, why = _material_weights(atlas, q["n"], q["k"])
    result["material"] = {"nearest": nearest, "from": [[atlas.materials[m], round(w, 4)] for m, w in mats]}
    why = why or _outside(atlas, q)
    advice = _advice(q)
    if advice:
        result["advice"] = advice
    if (q["shadowing"], q["diffuse"]) not in atlas.variants:
        why = why or f"the variant {q['shadowing']}/{q['diffuse']} is not in the atlas"
    if why:
        return _unknown(result, why)
    hb = _bracket(atlas.heights, q["sigma_h_wl"], "", "") if q["sigma_h_wl"] is not None else None
    heights = [hb] if hb is not None else [[h] for h in range(atlas.heights.size)]
    variant = atlas.variants.index((q["shadowing"], q["diffuse"]))
    per_height = _variant_at_height(atlas, q, mats, variant, heights)
    result["elements"] = _elements(atlas, per_height, q)
    result["region"] = _region_name(atlas, q)
    result["recommended"], result["variants"] = _recommend(atlas, q, mats, heights)
    result["coherent"] = _coherent(atlas, q, mats, heights)
    result["mom"] = _mom_cost(atlas, q, mats, heights)
    result["material"]["smooth_in_index"] = len(mats) < 2 or all(per_height[0][2] or [True]) \
        if per_height[0][0] is not None else None
    unknown = [name for name, e in result["elements"].items() if e.get("status") == "unknown"]
    result["status"] = "unknown" if unknown else "ok"
    result["reason"] = result["elements"][unknown[0]]["reason"] if unknown else None
    return result


def _region_name(atlas, q):
    if q["theta_r_deg"] is None:
        return "lobe"
    return "specular" if abs(q["theta_r_deg"] - q["theta_i_deg"]) <= q["spec"] else "lobe or wing (per node)"


def _advice(q):
    """What to use where the atlas does not reach: perturbation theory for a slightly rough surface."""
    h = q["sigma_h_wl"]
    if h is not None and 2.0 * math.pi * h * math.cos(math.radians(q["theta_i_deg"])) < _SLIGHT_ROUGHNESS:
        return ("slightly rough (k sigma_h cos theta_i < 0.3): perturbation theory (Rice) holds here, the geometric-"
                "optics model does not; the MoM answers exactly (docs/accuracy.md)")
    return None


def _unknown(result, why):
    result.update(status="unknown", reason=why, region=None,
                  elements={name: {"error": None, "se": None, "valid": None, "status": "unknown", "reason": why}
                            for name, _ in ELEMENTS_16},
                  recommended={"method": "mom", "shadowing": None, "diffuse": None, "reason": why})
    return result


def verdict(theta_i, rms_slope, n=None, k=None, *, sigma_h_wl=None, shadowing="vgroove", diffuse="paper",
            tol_db=TOLERANCE_DB, tol=TOLERANCE, atlas=None):
    """The atlas's verdict where an answer is made (a fit's incidence angles, a MoM run's): :func:`accuracy` at
    each incidence angle (radians, array-like), condensed.

    Returns a dict: ``per_angle`` [{"theta_i_deg", "status" ("valid" | "invalid" | "undecided" | "unknown"),
    "worst": [element, error, tolerance] of the element furthest beyond (or nearest to) its tolerance,
    "recommended": "shadowing/diffuse" | "mom"}], ``summary`` one line, ``answers`` the full answers.  An atlas
    that cannot be read gives status "unknown" with the reason (never an exception: a verdict is advice).
    """
    try:
        atlas = load_atlas() if atlas is None else atlas
    except UsageError as exc:
        return {"per_angle": [], "answers": [], "summary": f"accuracy atlas: unknown ({exc})"}
    per, answers = [], []
    for t in np.unique(np.atleast_1d(np.asarray(theta_i, float))):
        a = accuracy(float(t), rms_slope, n, k, sigma_h_wl=sigma_h_wl, shadowing=shadowing, diffuse=diffuse,
                     tol_db=tol_db, tol=tol, atlas=atlas)
        answers.append(a)
        per.append(_condense(a))
    return {"per_angle": per, "answers": answers, "summary": _summary(per, shadowing, diffuse)}


def _condense(a):
    """One answer as (status, worst element, recommendation)."""
    graded = [(name, a["elements"][name]) for name in ("M00_dB", "M01", "M11", "M22", "M23")]
    rec = a["recommended"]
    out = {"theta_i_deg": round(a["query"]["theta_i_deg"], 4),
           "recommended": "mom" if rec["method"] == "mom" else f"{rec['shadowing']}/{rec['diffuse']}"}
    if a["status"] == "unknown":
        return dict(out, status="unknown", reason=a["reason"], worst=None)
    ratio = [(e["error"] / e["tolerance"], name, e) for name, e in graded]
    r, name, e = max(ratio)
    status = ("invalid" if any(x["valid"] is False for _, x in graded) else
              "valid" if all(x["valid"] is True for _, x in graded) else "undecided")
    return dict(out, status=status, worst=[name, e["error"], e["tolerance"]])


def _summary(per, shadowing, diffuse):
    """'accuracy atlas (model vgroove/paper vs exact EM): valid at 10-30 deg; invalid at 60 deg (M22 0.31 > 0.1)...'"""
    if not per:
        return "accuracy atlas: no incidence angle"
    parts = []
    for status in ("valid", "undecided", "invalid", "unknown"):
        rows = [p for p in per if p["status"] == status]
        if not rows:
            continue
        angles = ", ".join(f"{p['theta_i_deg']:g}" for p in rows)
        if status == "invalid":
            w = max(rows, key=lambda p: p["worst"][1] / p["worst"][2])["worst"]
            parts.append(f"invalid at {angles} deg (worst {w[0]} error {w[1]:.3g} > {w[2]:g})")
        elif status == "unknown":
            parts.append(f"unknown at {angles} deg ({rows[0]['reason']})")
        else:
            parts.append(f"{status} at {angles} deg")
    recs = sorted({p["recommended"] for p in per if p["status"] != "unknown"})
    return (f"accuracy atlas (model {shadowing}/{diffuse} vs exact EM, 1-D surfaces): " + "; ".join(parts)
            + (f"; cheapest adequate: {', '.join(recs)}" if recs else ""))
