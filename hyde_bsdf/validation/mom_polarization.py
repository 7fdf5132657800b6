"""Checks of the two-polarisation, finite-index MoM that cannot be tuned (issue 11, part 2).

1. Flat-surface limit: one long smooth tapered plate (Eq. 22's window) of Infragold
   (eta = 0.285 - 7.3523 j), flame-sprayed aluminium (1.226 - 10.413 j) and glass (1.5)
   must reproduce the Fresnel reflectances |r_s|^2, |r_p|^2 (absolute error <= 0.01 of
   the incident power) and the phase arg(r_p / r_s) (<= 0.5 deg, where |r_p|^2 > 0.001:
   the phase is undefined at Brewster's angle), theta_i = 0-80 deg.  The plate is 300
   wavelengths (w = 75) up to 70 deg and 400 (w = 133) at 80 deg, so that Thorsos'
   parameter stays below 0.005; the quick mode stops at 70 deg on a 100-wavelength plate.
   Also reflected + absorbed = 1 within 1 % (absorbed power from the surface fields,
   Poynting) up to 70 deg; at 80 deg it is reported (edge waves of the truncated plate).
2. PEC p (and s) on the paper's Fig. 6 surface (rms slope 0.3, ell = 5 lambda, 100
   partitions of 150 lambda; quick: 10): power balance within 1 % in both polarisations.
3. Reciprocity of the bistatic sigma: sigma(theta_i = a -> theta_r = b) against
   sigma(b -> a) on the same run (the surface ensemble is mirror symmetric, so this holds
   within speckle): |difference| <= 3 combined standard errors for >= 90 % of the pairs.
4. Sampling: the issue-10 steep case (rms slope 8.5) is refused with a message naming the
   arc-length sampling; too few points per interior wavelength (glass at 6 pts/lambda) warns.

Writes mom_polarization.png (Fresnel errors per material) and mom_polarization.csv.
"""
import math
import time
import warnings
from pathlib import Path

import numpy as np

from hyde_bsdf.validation._common import cli, save_figure, write_csv  # noqa: E402

MATERIALS = [("Infragold", 0.285, 7.3523), ("flame-sprayed Al", 1.226, 10.413), ("glass", 1.5, 0.0)]
ELL = 5.0
SIGMA_H = 0.3 * ELL / math.sqrt(2.0)


def flat_plate(quick):
    from hyde_bsdf import mom
    from hyde_bsdf.model.fresnel import fresnel_rs_rp

    # (angles, plate length, taper width): the taper must be wide for grazing incidence (Thorsos'
    # parameter (1 + 2 tan^2 ti)/(k w cos ti)^2: 0.003 at 70 deg with w = 75, 0.004 at 80 deg with w = 133)
    groups = [(np.arange(0.0, 71.0, 10.0), 100.0, 25.0)] if quick else \
        [(np.arange(0.0, 71.0, 10.0), 300.0, 75.0), (np.array([80.0]), 400.0, 400.0 / 3.0)]
    rows = []
    for name, n, k in MATERIALS:
        for ti, length, w in groups:
            t0 = time.perf_counter()
            res = mom.scatter(length, 1, 0.0, 1.0, ti, ti, pts_per_wl=10, executor=mom.SerialExecutor(),
                              polarization=("s", "p"), n=n, k=k, progress=False, taper_width_wl=w)
            rs, rp = fresnel_rs_rp(np.cos(np.radians(ti)), n, k)
            # sigma_sp ~ r_s r_p*: its phase against Fresnel's
            dphase = np.degrees(np.angle(np.diag(res.sigma_sp) * (rp / rs)))
            for j, t in enumerate(ti):
                rows.append([name, t, abs(rs[j]) ** 2, res.power_balance_s[j], abs(rp[j]) ** 2,
                             res.power_balance_p[j], math.degrees(np.angle(rp[j] / rs[j])), dphase[j],
                             res.energy_s[j], res.energy_p[j], time.perf_counter() - t0])
    return rows


def fig6_both(quick):
    from hyde_bsdf import mom

    parts = 10 if quick else 100
    ti = [10.0, 30.0, 45.0, 60.0, 75.0]
    ex = mom.process_pool(2)
    try:
        res = mom.scatter(150.0 * parts, parts, SIGMA_H, ELL, ti, ti, pts_per_wl=10, seed=0, executor=ex,
                          polarization=("s", "p"), progress=False)
    finally:
        ex.shutdown()
    return ti, res


def reciprocity(ti, res):
    """Pairs a < b: sigma(a -> b) against sigma(b -> a), in combined standard errors."""
    out = []
    for pol in ("s", "p"):
        sig = getattr(res, "sigma_" + pol)
        se = getattr(res, f"sigma_{pol}_std_error")
        for i in range(len(ti)):
            for j in range(i + 1, len(ti)):
                d = abs(sig[i, j] - sig[j, i]) / math.hypot(se[i, j], se[j, i])
                out.append((pol, ti[i], ti[j], sig[i, j], sig[j, i], d))
    return out


def sampling_checks():
    from hyde_bsdf import mom

    refused = ""
    try:
        mom.scatter(300, 2, 30, 5.0, [30], np.arange(-89, 90.), pts_per_wl=10, seed=0, executor=mom.SerialExecutor())
    except ValueError as exc:
        refused = str(exc)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        mom.scatter(20.0, 1, 0.0, 1.0, 0.0, 0.0, pts_per_wl=6, executor=mom.SerialExecutor(), n=1.5, k=0.0)
    warned = [str(w.message) for w in caught if issubclass(w.category, mom.MoMAccuracyWarning)]
    return refused, warned


def chart(rows, path):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(10, 3.8))
    for name, _, _ in MATERIALS:
        r = [x for x in rows if x[0] == name]
        t = [x[1] for x in r]
        axes[0].plot(t, [x[3] - x[2] for x in r], "o-", ms=3, label=f"{name} s")
        axes[0].plot(t, [x[5] - x[4] for x in r], "s--", ms=3, label=f"{name} p")
        ok = [x for x in r if x[4] > 1e-3]
        axes[1].plot([x[1] for x in ok], [x[7] for x in ok], "o-", ms=3, label=name)
    axes[0].axhspan(-0.01, 0.01, color="0.9")
    axes[0].set(xlabel="theta_i (deg)", ylabel="MoM - Fresnel reflectance", title="|r|^2 error (band: 0.01)")
    axes[1].axhspan(-0.5, 0.5, color="0.9")
    axes[1].set(xlabel="theta_i (deg)", ylabel="deg", title="arg(r_p/r_s) error (band: 0.5 deg)")
    axes[0].legend(fontsize=6)
    axes[1].legend(fontsize=7)
    fig.suptitle("MoM flat-plate limit, both polarisations, 10 pts/lambda (default)", fontsize=9)
    save_figure(fig, path, tight=True)


def validate(outdir="out/validation", quick=False):
    out = Path(outdir)
    out.mkdir(parents=True, exist_ok=True)
    rows = flat_plate(quick)
    chart(rows, out / "mom_polarization.png")
    ti, res = fig6_both(quick)
    rec = reciprocity(ti, res)
    refused, warned = sampling_checks()
    csv_rows = [["flat"] + r for r in rows]
    csv_rows += [["fig6", "PEC " + pol, t, "", getattr(res, "power_balance_" + pol)[j], "", "", "", "", "", "", ""]
                 for pol in ("s", "p") for j, t in enumerate(ti)]
    csv_rows += [["reciprocity", pol, a, b, s_ab, s_ba, d, "", "", "", "", ""] for pol, a, b, s_ab, s_ba, d in rec]
    write_csv(out / "mom_polarization.csv",
              ["kind", "material", "theta_i_deg", "rs2_fresnel", "Rs_mom", "rp2_fresnel", "Rp_mom",
               "arg_rp_rs_fresnel_deg", "phase_error_deg", "energy_s", "energy_p", "seconds"], csv_rows)
    checks = []
    for name, _, _ in MATERIALS:
        r = [x for x in rows if x[0] == name]
        err = max(max(abs(x[3] - x[2]), abs(x[5] - x[4])) for x in r)
        ph = max(abs(x[7]) for x in r if x[4] > 1e-3)
        en = max(max(abs(x[8] - 1), abs(x[9] - 1)) for x in r if x[1] <= 70.0)
        span = f"{r[0][1]:g}-{r[-1][1]:g} deg"
        checks += [dict(name=f"MoM flat {name}: max |R - |r|^2| over s, p, {span}", value=f"{err:.4f}",
                        tolerance=0.01, passed=err <= 0.01),
                   dict(name=f"MoM flat {name}: max |arg(r_p/r_s) error| (deg), {span}", value=f"{ph:.3f}",
                        tolerance=0.5, passed=ph <= 0.5),
                   dict(name=f"MoM flat {name}: max |reflected + absorbed - 1|, 0-70 deg", value=f"{en:.4f}",
                        tolerance=0.01, passed=en <= 0.01)]
        grazing = [x for x in r if x[1] > 70.0]
        if grazing:
            # at 80 deg the truncated plate's ends launch a p-polarised edge wave along the metal; the surface
            # fields under the window absorb part of it (the far-field R is unaffected): reported, not a check
            checks.append(dict(name=f"MoM flat {name}: reflected + absorbed at 80 deg (s, p; edge waves of the "
                                    "truncated plate enter the absorbed power)",
                               value=f"{grazing[0][8]:.4f}, {grazing[0][9]:.4f}", tolerance="reported", passed=True))
    parts = res.params["partitions"]
    for pol in ("s", "p"):
        pb = getattr(res, "power_balance_" + pol)
        e = float(np.max(np.abs(pb - 1)))
        checks.append(dict(name=f"MoM PEC {pol}-pol power balance on the Fig. 6 surface ({parts} partitions), "
                                "max over theta_i 10-75 deg", value=f"{e:.4f}", tolerance=0.01, passed=e <= 0.01))
    frac = np.mean([d <= 3.0 for *_, d in rec])
    checks.append(dict(name="MoM reciprocity sigma(a->b) vs sigma(b->a): share of pairs within 3 std errors",
                       value=f"{frac:.2f} (max {max(d for *_, d in rec):.2f} se)", tolerance=">= 0.9",
                       passed=frac >= 0.9))
    checks.append(dict(name="MoM refuses the issue-10 steep surface (rms slope 8.5), naming the arc-length sampling",
                       value=refused[:90], tolerance="ValueError", passed="arc length" in refused))
    checks.append(dict(name="MoM warns at < 5 points per interior wavelength (glass, 6 pts/lambda)",
                       value=len(warned), tolerance=">= 1",
                       passed=any("interior wavelength" in w for w in warned)))
    return checks


if __name__ == "__main__":
    cli(validate, __doc__)
