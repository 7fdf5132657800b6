"""Paper Fig. 6: MoM reference for a 15,000-lambda random rough PEC surface against the pBRDF (Eq. 17).

The paper's case: a 1-D Gaussian surface 15,000 wavelengths long, cut into 100
partitions, rms slope sqrt(2) sigma_h / ell = 0.3, s-polarisation, theta_i =
10, 30, 45, 60, 75 deg, observation in the specular plane; both the MoM and the
model normalised at their specular values.

Which model quantity is compared with sigma(theta_r)
---------------------------------------------------
The MoM's sigma (Eq. 23) is power per unit scattering angle.  A BRDF F is
radiance over irradiance; the power it sends per unit (solid) angle is
proportional to F cos(theta_r).  So the curve compared with sigma(theta_r) is
``F00(theta_i, |theta_r|, phi) cos(theta_r)`` with phi = pi on the specular side
(theta_r >= 0) and phi = 0 on the backscatter side, from
``hyde_bsdf.pbrdf(..., rms_slope=0.3, pec=True)[..., 0, 0]``.  Both curves are
then divided by their value at theta_r = theta_i, as in the paper.  (For the
MoM, whose single-angle values carry speckle, the specular value is the mean of
sigma over theta_i +- 1 deg.)  The absolute, apples-to-apples comparison with
the model's own 1-D reduction is hyde_bsdf/validation/mom_1d_model.py.

Surface parameters
------------------
The paper gives only the ratio sqrt(2) sigma_h / ell = 0.3.  Geometrical optics
needs sigma_h and ell large against the wavelength; we take ell = 5 lambda and
sigma_h = 0.3 * 5 / sqrt(2) = 1.0607 lambda: k ell = 31, k sigma_h = 6.7 (the
coherent specular share exp(-(2 k sigma_h cos ti)^2) < 1e-5 even at 75 deg), and
the rms curvature radius ell^2 / (sqrt(12) sigma_h) = 6.8 lambda.  A partition
(150 lambda) then holds 30 correlation lengths.

Outputs (in -o OUTDIR, default out/validation/): fig6_mom.png, fig6_mom.csv
(curves), fig6_mom_table.csv (differences and power balance per theta_i), and
fig6_mom.npz (the raw MoM result, reused by mom_1d_model.py).
"""
from __future__ import annotations

import contextlib
import csv
import math
import os
import sys
import time

import numpy as np

from hyde_bsdf.validation._common import (db, flagged_legend, legend_entries, mom_parser, plot_flagged, save_figure,  # noqa: E402
                                          write_csv)

THETA_I_DEG = [10.0, 30.0, 45.0, 60.0, 75.0]
RMS_SLOPE = 0.3
CORR_LENGTH_WL = 5.0
RMS_HEIGHT_WL = RMS_SLOPE * CORR_LENGTH_WL / math.sqrt(2.0)
LENGTH_WL = 15000.0
PARTITIONS = 100
THETA_R_DEG = np.round(np.arange(-89.5, 89.51, 0.5), 6)
LOBE_LEVEL = 0.1  # the lobe: where the normalised pBRDF curve is >= 0.1 (-10 dB)


def run_mom(args):
    from hyde_bsdf import mom

    npz = os.path.join(args.outdir, "fig6_mom.npz")
    if args.reuse and os.path.exists(npz):
        data = dict(np.load(npz, allow_pickle=False))
        if "valid" in data:   # an older file without the flags is run again
            print(f"reusing {npz}", file=sys.stderr)
            return data
    res = mom.scatter(LENGTH_WL, PARTITIONS, RMS_HEIGHT_WL, CORR_LENGTH_WL, THETA_I_DEG, THETA_R_DEG,
                      pts_per_wl=args.pts_per_wl, seed=args.seed)
    data = {
        "theta_i_deg": res.theta_i_deg, "theta_r_deg": res.theta_r_deg, "sigma": res.sigma,
        "sigma_std_error": res.sigma_std_error, "sigma_coherent": res.sigma_coherent,
        "valid": res.valid, "floor_reason": np.str_(res.floor_reason),
        "power_balance": res.power_balance, "power_balance_nominal": res.power_balance_nominal,
        "power_coherent": res.power_coherent,
        "fine_theta_r": res.fine_theta_r, "fine_sigma": res.fine_sigma,
        "pts_per_wl": np.float64(args.pts_per_wl), "seed": np.int64(args.seed),
        "rms_height_wl": np.float64(RMS_HEIGHT_WL), "corr_length_wl": np.float64(CORR_LENGTH_WL),
        "taper_width_wl": np.float64(res.params["taper_width_wl"]),
        "times": np.array([res.times[k] for k in ("fill", "factor", "solve", "far_field", "wall")]),
    }
    np.savez(npz, **data)
    return data


def pbrdf_curve(theta_i_deg, theta_r_deg):
    """F00(theta_i, |theta_r|, phi) cos(theta_r) in the plane of incidence (phi = pi forward, 0 back)."""
    import hyde_bsdf

    ti = np.radians(theta_i_deg)
    tr = np.radians(theta_r_deg)
    phi = np.where(tr >= 0.0, math.pi, 0.0)
    F = hyde_bsdf.pbrdf(ti, np.abs(tr), phi, rms_slope=RMS_SLOPE, pec=True)[..., 0, 0]
    return F * np.cos(tr)


def specular_value(theta_r_deg, curve, theta_i_deg, half_width=1.0):
    """Mean of the curve over theta_i +- half_width degrees (the speckle-robust specular value)."""
    sel = np.abs(theta_r_deg - theta_i_deg) <= half_width + 1e-9
    return float(np.mean(curve[sel]))



def main(argv=None):
    ap = mom_parser(__doc__)
    ap.add_argument("--reuse", action="store_true", help="reuse OUTDIR/fig6_mom.npz if present")
    args = ap.parse_args(argv)
    os.makedirs(args.outdir, exist_ok=True)

    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from hyde_bsdf.mom import model1d

    t0 = time.perf_counter()
    d = run_mom(args)
    tr = d["theta_r_deg"]
    rows, table = [], []
    fig, axes = plt.subplots(1, len(THETA_I_DEG), figsize=(4.0 * len(THETA_I_DEG), 4.8), sharey=True)
    for i, ti in enumerate(THETA_I_DEG):
        s = d["sigma"][i]
        se = d["sigma_std_error"][i]
        s0 = specular_value(tr, s, ti)
        mom_n = s / s0
        model = pbrdf_curve(ti, tr)
        model_n = model / float(pbrdf_curve(ti, np.array([ti]))[0])
        m1d = model1d.sigma_equivalent(np.radians(ti), np.radians(tr), RMS_SLOPE)
        m1d_n = m1d / float(model1d.sigma_equivalent(np.radians(ti), np.radians([ti]), RMS_SLOPE)[0])
        lobe = model_n >= LOBE_LEVEL
        diff = db(mom_n[lobe]) - db(model_n[lobe])
        diff1d = db(mom_n[lobe]) - db(m1d_n[lobe])
        # peak positions: MoM smoothed over +-2 deg to keep speckle from picking the maximum
        kern = np.ones(9) / 9.0
        mom_smooth = np.convolve(mom_n, kern, mode="same")
        table.append({
            "theta_i_deg": ti,
            "lobe_from_deg": float(tr[lobe].min()), "lobe_to_deg": float(tr[lobe].max()),
            "rms_diff_dB": float(np.sqrt(np.mean(diff**2))), "mean_diff_dB": float(np.mean(diff)),
            "max_abs_diff_dB": float(np.max(np.abs(diff))),
            "rms_diff_1d_model_dB": float(np.sqrt(np.mean(diff1d**2))),
            "mean_diff_1d_model_dB": float(np.mean(diff1d)),
            "mom_peak_deg": float(tr[np.argmax(mom_smooth)]), "pbrdf_peak_deg": float(tr[np.argmax(model_n)]),
            "mom_speckle_rms_dB": float(np.sqrt(np.mean((db(1 + se[lobe] / s[lobe]) ** 2)))),
            "power_balance": float(d["power_balance"][i]),
            "power_balance_nominal": float(d["power_balance_nominal"][i]),
            "power_coherent": float(d["power_coherent"][i]),
        })
        for j in range(tr.size):
            rows.append([ti, tr[j], s[j], se[j], mom_n[j], model_n[j], m1d_n[j], int(d["valid"][i][j])])
        ax = axes[i]
        plot_flagged(ax, tr, mom_n, d["valid"][i], str(d["floor_reason"]), color="k", lw=0.8,
                     label="MoM (1-D surface)")
        ax.plot(tr, model_n, "r--", lw=1.5, label="pBRDF Eq. 17: F00 cos(tr)")
        ax.plot(tr, m1d_n, "b:", lw=1.5, label="pBRDF 1-D reduction")
        ax.axvline(ti, color="0.7", lw=0.5)
        ax.set_title(f"theta_i = {ti:g} deg, power {d['power_balance'][i]:.4f}")
        ax.set_xlabel("theta_r (deg, + = specular side)")
        ax.set_xlim(-90, 90)
    axes[0].set_ylabel("normalised at theta_r = theta_i")
    axes[0].legend(*legend_entries([axes[0]], False), loc="upper left", fontsize=7)
    below = flagged_legend(fig, loc="lower center", fontsize=6) * 1.0 / fig.get_figheight()   # the reason, once
    fig.suptitle(f"Fig. 6: {LENGTH_WL:g} lambda PEC surface, {PARTITIONS} partitions, rms slope {RMS_SLOPE}, "
                 f"sigma_h = {RMS_HEIGHT_WL:.4f}, ell = {CORR_LENGTH_WL:g} lambda, "
                 f"{float(d['pts_per_wl']):g} pts/lambda, s-pol")
    fig.tight_layout(rect=(0, below, 1, 1))
    png = os.path.join(args.outdir, "fig6_mom.png")
    save_figure(fig, png, dpi=120)
    write_csv(os.path.join(args.outdir, "fig6_mom.csv"),
              ["theta_i_deg", "theta_r_deg", "sigma_mom", "sigma_mom_std_error", "mom_normalized",
                    "pbrdf_F00_cos_normalized", "model1d_normalized", "valid_s"],
              [[f"{v:.6g}" for v in r] for r in rows])
    with open(os.path.join(args.outdir, "fig6_mom_table.csv"), "w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=list(table[0]))
        w.writeheader()
        for r in table:
            w.writerow({k: (f"{v:.4f}" if isinstance(v, float) else v) for k, v in r.items()})

    print("| theta_i | lobe (deg) | MoM - pBRDF rms / mean / max dB | MoM - 1-D model rms / mean dB "
          "| peak MoM / pBRDF (deg) | speckle rms dB | power balance (nominal) | coherent |")
    print("|---|---|---|---|---|---|---|---|")
    for r in table:
        print(f"| {r['theta_i_deg']:g} | {r['lobe_from_deg']:g} .. {r['lobe_to_deg']:g} "
              f"| {r['rms_diff_dB']:.2f} / {r['mean_diff_dB']:+.2f} / {r['max_abs_diff_dB']:.2f} "
              f"| {r['rms_diff_1d_model_dB']:.2f} / {r['mean_diff_1d_model_dB']:+.2f} "
              f"| {r['mom_peak_deg']:g} / {r['pbrdf_peak_deg']:g} | {r['mom_speckle_rms_dB']:.2f} "
              f"| {r['power_balance']:.4f} ({r['power_balance_nominal']:.4f}) | {r['power_coherent']:+.4f} |")
    t = d["times"]
    print(f"MoM times (worker CPU s): fill {t[0]:.1f}, factor {t[1]:.1f}, solve {t[2]:.1f}, far field {t[3]:.1f}; "
          f"wall {t[4]:.1f} s; script {time.perf_counter() - t0:.1f} s")
    print(f"wrote {png}")
    # the energy check: reflected over the incident power on the windowed partitions (tilt included);
    # the nominal one (Eq. 23's flat-surface normaliser) also carries the sample's tilt noise
    bad = [r["theta_i_deg"] for r in table if abs(r["power_balance"] - 1.0) > 0.01]
    if bad:
        print(f"POWER BALANCE OFF BY > 1 % at theta_i = {bad}", file=sys.stderr)
        return 1
    return 0


def _read_table(path):
    with open(path, newline="") as fh:
        return [{k: float(v) for k, v in r.items()} for r in csv.DictReader(fh)]


#: the quick report's case: 1/5 of the paper's surface (3000 lambda, 20 partitions)
QUICK_LENGTH_WL, QUICK_PARTITIONS = 3000.0, 20


@contextlib.contextmanager
def surface(quick):
    """The Fig. 6 surface of the run inside the block: the quick report's (QUICK_LENGTH_WL,
    QUICK_PARTITIONS) when ``quick``, else the paper's; yields the paper's (length, partitions)."""
    global LENGTH_WL, PARTITIONS
    saved = LENGTH_WL, PARTITIONS
    if quick:
        LENGTH_WL, PARTITIONS = QUICK_LENGTH_WL, QUICK_PARTITIONS
    try:
        yield saved
    finally:
        LENGTH_WL, PARTITIONS = saved


def validate(outdir="out/validation", quick=False):
    """The report's checks: power balance (1 %), MoM vs the model's 1-D reduction (dB), and the
    paper's comparison with Eq. 17 (reported; see the README for why it differs at 60-75 deg)."""
    with surface(quick) as saved:
        main(["-o", str(outdir)])
    table = _read_table(os.path.join(str(outdir), "fig6_mom_table.csv"))
    size = f"{QUICK_LENGTH_WL:g} lambda / {QUICK_PARTITIONS}" if quick else f"{saved[0]:g} lambda / {saved[1]}"
    checks = []
    for r in table:
        ti = r["theta_i_deg"]
        # sampling noise of a finite surface: +-0.5 % at 100 partitions, ~ +-1.1 % at 20 (quick)
        ptol = 0.02 if quick else 0.01
        checks.append(dict(name=f"Fig6 MoM power balance, theta_i = {ti:g} deg ({size} partitions)",
                           value=r["power_balance"], tolerance=f"1 +- {ptol}",
                           passed=abs(r["power_balance"] - 1) <= ptol))
        tol = 2.5 if quick else 1.5      # speckle: ~0.45 dB at 100 partitions, ~1 dB at 20
        checks.append(dict(name=f"Fig6 MoM vs pBRDF 1-D reduction over the lobe, theta_i = {ti:g} deg (rms dB)",
                           value=r["rms_diff_1d_model_dB"], tolerance=tol, passed=r["rms_diff_1d_model_dB"] <= tol))
        checks.append(dict(name=f"Fig6 MoM vs Eq. 17 (2-D model, normalised as in the paper), theta_i = {ti:g} deg (rms dB)",
                           value=r["rms_diff_dB"], tolerance="reported", passed=True))
    from hyde_bsdf.validation._common import atlas_checks
    checks += atlas_checks("Fig6 MoM vs the model", [r["theta_i_deg"] for r in table], RMS_SLOPE, RMS_HEIGHT_WL,
                           [("PEC", None, None)])
    return checks


if __name__ == "__main__":
    from hyde_bsdf.validation._common import cli
    cli(validate, __doc__, main)
