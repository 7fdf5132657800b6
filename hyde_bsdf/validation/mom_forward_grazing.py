"""Forward grazing in s: the windowed current's artificial floor, and the Gaussian beam that removes it (issue 25).

The paper's Eq. 22 windows the *current* of a plane-wave-lit partition.  A windowed current radiates the window's
spectrum without the obliquity of a real reflected wave: in s on a PEC its far field near theta_r -> 90 deg stays at
cos(ti)^2 |W^|^2 where a beam's reflected wave falls as cos(theta_r)^2 -- (cos 80 / cos 87)^2 = 11, 10.4 dB too
strong at 87 deg for 80-deg incidence.  ``incidence="beam"`` (:mod:`hyde_bsdf.mom.beam`) lights the partition with
an exact Gaussian beam and radiates the unwindowed currents.

1. Flat PEC plate, theta_i = 80 deg, w = 75 lambda, partition 4 w (and 6 w), 10 pts/lambda: sigma_s, sigma_p of both
   incidences against the independent analytic result -- the beam's reflected wave off an infinite PEC plane,
   sigma_ref(theta) = 2 pi cos(ti) cos^2(theta) |A(k sin theta)|^2 / int cos^2 |A|^2 d theta (energy conservation
   fixes the scale; A the beam's spectrum), which is ~e^-700 at 87 deg: the MoM's value there is its floor.
2. Rough PEC surface, the Fig. 6 statistics (rms slope 0.3, ell = 5 lambda), theta_i = 80 deg, w = 150 lambda, on
   the same partitions: window (partitions 4 w) against beam (4 w), 1-deg bins at theta_r = 86-89 deg (reported);
   the beam on 6 w partitions (another realisation) against 4 w within 3 dB plus twice the speckle.
   Quick mode: 2 partitions (full: 8); part 3's grid at theta_i = 80/85/88 deg, w = 37.5/75 lambda (full: five angles
   80-88 deg, w 37.5-300 lambda).

Measured (docs/validation.md): the flat plate's analytic sigma at 86/87/88/89 deg is -82/-99/-113/-126 dB below the
specular peak; the windowed current sits at -44.5 dB (4 w) and -50 dB (6 w) in s -- the artificial floor: the
plane-wave-lit partition ends launch surface waves (s: decaying only as x^-3/2) that reach the window and radiate
at forward grazing -- and follows the reference in p at 6 w; the beam follows it to -98 dB at 6 w (its floor at
4 w, -54 to -59 dB, is the beam's e^-4 at the partition ends).  On the rough surface the incoherent field is
20-50 dB above these floors and window and beam agree within 0.3-2.6 dB.

3. Issue 25's target, graded: on flat PEC plates (GRID_TI x GRID_W x 4w/6w, beam and window, s and p) every sigma
   reported valid at 86-89 deg is within 3 dB of the analytic result (measured: within 1.93 dB).  The windowed
   current's s carries its coherent reflection's obliquity, cos^2 ti for cos^2 theta_r (+7.9 dB at 86 deg for
   80-deg incidence), which the floor estimate now flags (:mod:`hyde_bsdf.mom.floor`).
4. The grazing zone's cause: the MoM against the infinite-plane current cut to the partition
   (:func:`truncated_plane_db`), and partitions of 4 w against 6 w at 85 and 88 deg, error against CPU cost.

Writes mom_forward_grazing.csv (sigma per case and theta_r, valid_s / valid_p per case), mom_forward_grazing.png
(flagged angles grey, with the reason), mom_forward_grazing_cost.csv, mom_forward_grazing_valid.csv (the grid),
mom_forward_grazing_width.csv and .png (4 w against 6 w), and the checks.
"""
import math
import warnings
from pathlib import Path

import numpy as np

from hyde_bsdf.validation._common import cli, db, flagged_legend, legend_entries, plot_flagged, save_figure, write_csv  # noqa: E402

K0 = 2.0 * math.pi
ELL = 5.0
SIGMA_H = 0.3 * ELL / math.sqrt(2.0)
THETA_R = np.arange(60.0, 89.76, 0.25)
FLAT = dict(theta_i=80.0, w=75.0)
ROUGH = dict(theta_i=80.0, w=150.0)
BANDS = (86.0, 87.0, 88.0, 89.0)
#: the grid of flat PEC plates on which "within 3 dB of the analytic result wherever reported valid" is graded at
#: theta_r = 86-89 deg: theta_i, taper widths (lambda; quick mode GRID_W_QUICK), partition lengths / w
GRID_TI = (80.0, 83.0, 85.0, 87.0, 88.0)
GRID_W = (37.5, 75.0, 150.0, 300.0)
GRID_W_QUICK = (37.5, 75.0)
#: the quick grid's theta_i: the far-from-grazing end (80 deg, part 1's plate), the middle and the most grazing end,
#: which are the width study's angles too (their w = 75 plates are solved once for both); 83 and 87 deg lie between
#: them on the same floor physics (the partition's floor against cos^2 theta_r), graded in the full run
GRID_TI_QUICK = (80.0, 85.0, 88.0)
GRID_L = (4, 6)
#: partitions of 4 w against 6 w at grazing incidence (error against cost): theta_i, taper widths (quick mode:
#: WIDTH_W_QUICK)
WIDTH_TI = (85.0, 88.0)
WIDTH_W = (50.0, 75.0, 100.0, 150.0, 300.0)
WIDTH_W_QUICK = (75.0, 150.0)


def beam_reference(theta_i_deg, w, theta_r_deg):
    """sigma of the beam's reflected wave off an infinite flat PEC (analytic; scale from energy conservation)."""
    ti = math.radians(theta_i_deg)
    th = np.linspace(-math.pi / 2, math.pi / 2, 400001)
    dens = lambda t: np.cos(t) ** 2 * np.exp(-(w * K0 * (np.sin(t) - math.sin(ti))) ** 2 / 2.0)  # noqa: E731
    total = np.trapezoid(dens(th), th)
    return 2.0 * math.pi * math.cos(ti) * dens(np.radians(theta_r_deg)) / total


def truncated_plane_db(theta_i_deg, w, length, theta_r_deg, pol):
    """sigma of the infinite PEC plane's current cut to the partition |x| < L/2, over the analytic sigma, in dB: the
    current's spectrum f(K) = A(K) (p) or k_z A(K) (s), |K| <= k, convolved with the partition's L sinc((K' - K) L/2),
    at K' = k sin theta_r (independent of the MoM: the cause of the deviation at theta_r -> 90 deg)."""
    ti = math.radians(theta_i_deg)
    u = np.linspace(-math.pi / 2, math.pi / 2, 40001)
    K, dK = K0 * np.sin(u), K0 * np.cos(u) * (u[1] - u[0])
    f = np.exp(-(w * (K - K0 * math.sin(ti))) ** 2 / 4.0) * (K0 * np.cos(u) if pol == "s" else 1.0)
    out = []
    for t in np.radians(np.atleast_1d(theta_r_deg)):
        kt = K0 * math.sin(t)
        cut = np.sum(f * length * np.sinc((kt - K) * length / (2.0 * math.pi)) * dK)
        out.append(20.0 * math.log10(abs(cut) / (2.0 * math.pi * np.interp(kt, K, f))))
    return np.array(out)


#: the runs made so far in this process, {arguments of :func:`timed_run`: (result, CPU s)}: the flat plates of part 1
#: and of the width study are cases of the grid too (80 deg, w 75; 85 and 88 deg, w 75), each solved once
_RUNS = {}


def timed_run(length, partitions, sigma_h, w, theta_i, incidence, seed=3):
    """(MoM result, this process's CPU seconds for it) of one run (s and p, fast solver, 10 pts/lambda); a run with
    the same arguments as an earlier one returns that one's result and CPU seconds (deterministic: same seed)."""
    import time

    from hyde_bsdf import mom

    key = (float(length), int(partitions), float(sigma_h), float(w), float(theta_i), incidence, int(seed))
    if key not in _RUNS:
        t0 = time.process_time()
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", mom.MoMAccuracyWarning)
            res = mom.scatter(length, partitions, sigma_h, ELL, [theta_i], THETA_R, pts_per_wl=10, seed=seed,
                              executor=mom.SerialExecutor(), taper_width_wl=w, polarization=("s", "p"),
                              solver="fast", incidence=incidence, progress=False)
        _RUNS[key] = (res, time.process_time() - t0)
    return _RUNS[key]


def run(length, partitions, sigma_h, w, theta_i, incidence, seed=3):
    """The MoM result of :func:`timed_run`."""
    return timed_run(length, partitions, sigma_h, w, theta_i, incidence, seed)[0]



def band_means(res_sigma):
    """Mean sigma over theta_r in [a - 0.5, a + 0.5) for a in BANDS (1-deg bins)."""
    return np.array([res_sigma[(THETA_R >= a - 0.5) & (THETA_R < a + 0.5)].mean() for a in BANDS])


def validate(outdir="out/validation", quick=False):
    out = Path(outdir)
    out.mkdir(parents=True, exist_ok=True)
    ti, w = FLAT["theta_i"], FLAT["w"]
    flat = {name: run(f * w, 1, 0.0, w, ti, inc) for name, inc, f in
            (("window 4w", "window", 4), ("beam 4w", "beam", 4), ("window 6w", "window", 6), ("beam 6w", "beam", 6))}
    ref = beam_reference(ti, w, THETA_R)
    M = 2 if quick else 8
    rw = ROUGH["w"]
    rough = {name: run(f * rw * M, M, SIGMA_H, rw, ROUGH["theta_i"], inc) for name, inc, f in
             (("window 4w", "window", 4), ("beam 4w", "beam", 4), ("beam 6w", "beam", 6))}
    rows = []
    for j, tr in enumerate(THETA_R):
        row = [tr, ref[j]]
        for case in (flat, rough):
            for res in case.values():
                row += [res.sigma_s[0, j], res.sigma_p[0, j], int(res.valid_s[0, j]), int(res.valid_p[0, j])]
        rows.append(row)
    head = ["theta_r_deg", "flat_reference_s_and_p"]
    for tag, case in (("flat", flat), ("rough", rough)):
        for name in case:
            key = f"{tag}_{name.replace(' ', '_')}"
            head += [f"{key}_sigma_s", f"{key}_sigma_p", f"{key}_valid_s", f"{key}_valid_p"]
    write_csv(out / "mom_forward_grazing.csv", head, rows)
    write_csv(out / "mom_forward_grazing_cost.csv",
              ["case", "cpu_s", "unknowns", "energy_error_s", "energy_error_p", "sigma_s_88_dB_below_peak"],
              cost_rows(flat, ref))
    figure(flat, rough, ref, out / "mom_forward_grazing.png")
    grid = valid_grid(quick)
    write_csv(out / "mom_forward_grazing_valid.csv",
              ["theta_i_deg", "taper_w_wl", "partition_over_w", "incidence", "pol", "valid_86_89", "angles_86_89",
               "max_abs_error_dB_where_valid", "theta_r_of_max_deg", "cpu_s"], grid)
    width = width_study(quick)
    write_csv(out / "mom_forward_grazing_width.csv",
              ["theta_i_deg", "taper_w_wl", "partition_over_w", "pol", "cpu_s", "max_abs_error_dB_86_89_outside_zone",
               "angles_compared", "valid_86_89", "angles_86_89", "max_abs_dB_mom_minus_cut_plane_86_89.75"], width)
    width_figure(width, out / "mom_forward_grazing_width.png")
    return checks(flat, rough, ref) + [grid_check(grid)] + width_checks(width)


def width_study(quick):
    """Flat PEC, beam, WIDTH_TI x WIDTH_W, partitions of 4 w and 6 w: worker CPU s; the largest |sigma - analytic| at
    86-89 deg outside the grazing zone where the analytic is above -90 dB of its peak (what the floor does to a
    result read without its flags); the angles reported valid there; and at 86-89.75 deg the MoM against the cut
    infinite-plane current (:func:`truncated_plane_db`)."""
    from hyde_bsdf.mom.floor import GRAZING_ZONE

    band, tail = (THETA_R >= 85.5) & (THETA_R < 89.5), THETA_R >= 86.0
    rows = []
    for ti in WIDTH_TI:
        for w in WIDTH_W_QUICK if quick else WIDTH_W:
            ref = beam_reference(ti, w, THETA_R)
            zone = 90.0 - THETA_R < math.degrees(GRAZING_ZONE / (K0 * w * math.cos(math.radians(ti))))
            seen = band & ~zone & (ref >= 1e-9 * ref.max())
            for f in (4, 6):
                res, cpu = timed_run(f * w, 1, 0.0, w, ti, "beam")
                for pol in ("s", "p"):
                    err = db(getattr(res, "sigma_" + pol)[0]) - db(ref)
                    cut = err[tail] - truncated_plane_db(ti, w, f * w, THETA_R[tail], pol)
                    rows.append([ti, w, f, pol, cpu, float(np.abs(err[seen]).max()) if seen.any() else float("nan"),
                                 int(seen.sum()), int((getattr(res, "valid_" + pol)[0] & band).sum()), int(band.sum()),
                                 float(np.abs(cut).max())])
    return rows


def width_checks(rows):
    """The cut infinite-plane current explains the grazing zone (p graded at 0.3 dB, s reported); per theta_i and w
    the cost and the error of 6 w against 4 w (reported)."""
    out = []
    for pol, tol in (("p", 0.3), ("s", "reported")):
        worst = max(r[9] for r in rows if r[3] == pol)
        out.append(dict(name=f"MoM grazing zone, flat PEC, beam, {pol}: max |MoM - cut infinite-plane current| (dB) at "
                             "theta_r 86-89.75 deg (theta_i 85/88 deg, 4w and 6w): the partition cuts the current's "
                             "tail that the spectrum ending at grazing leaves",
                        value=f"{worst:.2f}", tolerance=tol, passed=worst <= tol if pol == "p" else True))
    for ti, w in sorted({(r[0], r[1]) for r in rows}):
        four, six = ([r for r in rows if r[0] == ti and r[1] == w and r[2] == f] for f in (4, 6))
        out.append(dict(name=f"MoM partitions 6w against 4w, flat PEC, beam, {ti:g} deg, w = {w:g}: CPU s; max |error| "
                             "(dB) s / p at 86-89 deg outside the grazing zone; valid angles s / p of 16",
                        value=f"{four[0][4]:.2f} -> {six[0][4]:.2f} s ({six[0][4] / four[0][4]:.2f} x); "
                              f"{four[0][5]:.1f} / {four[1][5]:.1f} -> {six[0][5]:.1f} / {six[1][5]:.1f} dB; "
                              f"{four[0][7]} / {four[1][7]} -> {six[0][7]} / {six[1][7]}",
                        tolerance="reported", passed=True))
    return out


def width_figure(rows, path):
    """Error against cost: per theta_i, the largest |sigma - analytic| at 86-89 deg (outside the grazing zone) of s
    and p against the worker CPU s, partitions of 4 w and 6 w, each point labelled with w."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    angles = sorted({r[0] for r in rows})
    fig, axes = plt.subplots(1, len(angles), figsize=(5.5 * len(angles), 4.2), squeeze=False)
    for ax, ti in zip(axes[0], angles):
        for f, marker in ((4, "o"), (6, "s")):
            for pol, col in (("s", "C0"), ("p", "C3")):
                sel = [r for r in rows if r[0] == ti and r[2] == f and r[3] == pol]
                ax.semilogy([r[4] for r in sel], [max(r[5], 0.01) for r in sel], marker + ("-" if f == 4 else "--"),
                            color=col, label=f"L = {f} w, {pol}")
                for r in sel:
                    ax.annotate(f"w {r[1]:g}", (r[4], max(r[5], 0.01)), fontsize=6, xytext=(3, 3),
                                textcoords="offset points")
        ax.axhline(3.0, color="0.5", lw=0.8, ls=":")
        ax.set(xlabel="worker CPU s (one flat partition, s + p)", ylabel="max |sigma - analytic| (dB), 86-89 deg",
               title=f"Flat PEC, beam, theta_i = {ti:g} deg (dotted: 3 dB)")
        ax.legend(fontsize=7)
    fig.tight_layout()
    save_figure(fig, path)


def valid_grid(quick):
    """Issue 25's target on flat PEC plates (GRID_TI x GRID_W x GRID_L, beam and windowed current, s and p): at
    theta_r = 86-89 deg, the largest |sigma - analytic reflected beam| (dB) over the angles reported valid."""
    band = (THETA_R >= 85.5) & (THETA_R < 89.5)
    rows = []
    for ti in GRID_TI_QUICK if quick else GRID_TI:
        for w in GRID_W_QUICK if quick else GRID_W:
            ref = beam_reference(ti, w, THETA_R)
            for f in GRID_L:
                for inc in ("beam", "window"):
                    res, cpu = timed_run(f * w, 1, 0.0, w, ti, inc)
                    for pol in ("s", "p"):
                        use = band & getattr(res, "valid_" + pol)[0]
                        err = np.abs(db(getattr(res, "sigma_" + pol)[0]) - db(ref))
                        j = int(np.argmax(np.where(use, err, -1.0)))
                        rows.append([ti, w, f, inc, pol, int(use.sum()), int(band.sum()),
                                     float(err[j]) if use.any() else 0.0, float(THETA_R[j]) if use.any() else "",
                                     cpu])
    return rows


def grid_check(grid):
    """One graded check over the grid: every sigma reported valid at 86-89 deg within 3 dB of the analytic result."""
    worst = max(grid, key=lambda r: r[7])
    n_valid = sum(r[5] for r in grid)
    widths = "/".join(f"{v:g}" for v in sorted({r[1] for r in grid}))
    angles = "/".join(f"{t:g}" for t in sorted({r[0] for r in grid}))
    return dict(name=f"MoM forward grazing: flat PEC grid (theta_i {angles} deg, "
                     f"w {widths} lambda, L 4w/6w, beam and window, s and p): "
                     f"max |sigma - analytic| (dB) over the {n_valid} of {sum(r[6] for r in grid)} sigma at 86-89 deg "
                     f"reported valid (worst: {worst[0]:g} deg, w {worst[1]:g}, {worst[2]}w, {worst[3]}, {worst[4]})",
                value=f"{worst[7]:.2f}", tolerance=3.0, passed=worst[7] <= 3.0)


def band_error_db(res, pol):
    """Speckle of the 1-deg band means in dB: the partitions' standard error, averaged over the bin (conservative:
    the samples of a bin are correlated)."""
    sig, se = getattr(res, "sigma_" + pol)[0], getattr(res, f"sigma_{pol}_std_error")[0]
    return (10.0 / math.log(10.0)) * band_means(se) / band_means(sig)


def checks(flat, rough, ref):
    ref_b = band_means(ref)
    peak = float(ref.max())
    out = []
    for name, res in flat.items():
        for pol in ("s", "p"):
            out.append(valid_check(f"flat PEC 80 deg, w = 75, {name}", res, pol, ref, graded=True))
    for tag, case in (("rough", rough),):
        for name, res in case.items():
            for pol in ("s", "p"):
                v = getattr(res, "valid_" + pol)[0][THETA_R >= 85.5]
                out.append(dict(name=f"MoM forward grazing: rough PEC 80 deg, w = 150, {name}, {pol}: share of theta_r "
                                     "in 85.5-89.75 deg reported valid (sigma >= 20 x the partition's floor)",
                                value=f"{v.mean():.2f}", tolerance="reported", passed=True))
    for name, res in flat.items():
        for pol in ("s", "p"):
            lvl = db(band_means(getattr(res, "sigma_" + pol)[0]) / peak)
            ok = (np.abs(lvl - db(ref_b / peak)) <= 3.0) | (lvl < -80.0)
            graded = name == "beam 6w"
            analytic = ", ".join(f"{v:.0f}" for v in db(ref_b / peak))
            out.append(dict(name=f"MoM forward grazing: flat PEC 80 deg, w = 75, {name}, {pol}: sigma at 86/87/88/89 "
                                 f"deg relative to the specular peak (analytic {analytic} dB); within 3 dB of it or "
                                 "below -80 dB (the solver's floor at tol 1e-4)"
                                 + ("" if graded else ", reported"),
                            value=", ".join(f"{v:.1f}" for v in lvl), tolerance=3.0 if graded else "reported",
                            passed=bool(np.all(ok)) if graded else True))
    for name, against in (("window 4w", "beam 4w"), ("beam 6w", "beam 4w")):
        for pol in ("s", "p"):
            a, b = rough[name], rough[against]
            d = db(band_means(getattr(a, "sigma_" + pol)[0]) / band_means(getattr(b, "sigma_" + pol)[0]))
            tol = 3.0 + 2.0 * np.hypot(band_error_db(a, pol), band_error_db(b, pol))
            same = name.startswith("window")
            what = (" on the same partitions (the windowed current's excess), reported" if same else
                    " (other partitions: within 3 dB + 2 speckle errors)")
            limits = "" if same else " (limits " + ", ".join(f"{t:.1f}" for t in tol) + ")"
            out.append(dict(name=f"MoM forward grazing: rough PEC 80 deg, w = 150, {name} against {against}, {pol}: "
                                 "dB at 86/87/88/89 deg" + what,
                            value=", ".join(f"{v:+.1f}" for v in d) + limits,
                            tolerance="reported" if same else "3 dB + 2 se",
                            passed=True if same else bool(np.all(np.abs(d) <= tol))))
    for tag, case in (("flat", flat), ("rough", rough)):
        for name, res in case.items():
            out.append(dict(name=f"MoM forward grazing: {tag} {name}, reflected power s / p (energy)",
                            value=f"{res.energy_s[0]:.4f} / {res.energy_p[0]:.4f}", tolerance="reported", passed=True))
    return out


def valid_check(label, res, pol, ref, graded):
    """Issue 25's target: within 3 dB of the analytic result at 86-89 deg wherever the result is reported valid
    (``MoMResult.valid_s`` / ``valid_p``: sigma at least 20 x the estimated floor of the truncated partition)."""
    sig, valid = getattr(res, "sigma_" + pol)[0], getattr(res, "valid_" + pol)[0]
    band = (THETA_R >= 85.5) & (THETA_R < 89.5)
    use = band & valid
    err = np.abs(db(sig[use] / ref[use])) if use.any() else np.zeros(1)
    return dict(name=f"MoM forward grazing: {label}, {pol}: |sigma - analytic| (dB) where reported valid at 86-89 deg "
                     f"({int(use.sum())} of {int(band.sum())} angles valid; the rest flagged: {res.floor_reason})"
                     + ("" if graded else ", reported"),
                value=f"{err.max():.2f}", tolerance=3.0 if graded else "reported",
                passed=bool(err.max() <= 3.0) if graded else True)


def sigma_panel(ax, results, scale, colours, **axis):
    """sigma_s (solid) and sigma_p (dashed) of each run over theta_r in dB of ``scale``, flagged angles grey
    (:func:`_common.plot_flagged`; the reason of each partition length in the figure's legend), the 86-89 deg band
    shaded."""
    for (name, res), col in zip(results.items(), colours):
        plot_flagged(ax, THETA_R, db(res.sigma_s[0] / scale), res.valid_s[0], res.floor_reason, color=col,
                     label=f"{name} s")
        plot_flagged(ax, THETA_R, db(res.sigma_p[0] / scale), res.valid_p[0], res.floor_reason, ls="--", color=col,
                     label=f"{name} p")
    ax.set(xlabel="theta_r (deg)", **axis)
    ax.axvspan(85.5, 89.5, color="0.92", zorder=0)
    ax.legend(*legend_entries([ax], False), fontsize=6)


def cost_rows(flat, ref):
    """Error against cost of each choice on the flat plate: worker CPU seconds, |energy - 1| per polarisation and
    the s level at 88 deg relative to the specular peak (analytic: -113 dB)."""
    peak = float(ref.max())
    at88 = (THETA_R >= 87.5) & (THETA_R < 88.5)
    return [[name, sum(v for k, v in res.times.items() if k != "wall"), res.params["unknowns_per_partition"],
             abs(res.energy_s[0] - 1.0), abs(res.energy_p[0] - 1.0), float(db(res.sigma_s[0, at88].mean() / peak))]
            for name, res in flat.items()]


def figure(flat, rough, ref, path):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 3, figsize=(16, 6))
    peak = float(ref.max())
    axes[0].plot(THETA_R, db(ref / peak), "k-", lw=2, label="analytic beam reflection")
    sigma_panel(axes[0], flat, peak, ("C3", "C0", "C1", "C2"), ylim=(-90, 5), ylabel="sigma / specular peak (dB)",
                title="Flat PEC plate, theta_i = 80 deg, w = 75 lambda")
    sigma_panel(axes[1], rough, 1.0, ("C3", "C0", "C2"), ylim=(-45, 15), ylabel="sigma (dB)",
                title="Rough PEC (slope 0.3, ell 5), theta_i 80 deg, w 150 lambda")
    ax = axes[2]
    for (name, cpu, _, es, ep, floor), col in zip(cost_rows(flat, ref), ("C3", "C0", "C1", "C2")):
        ax.semilogy(cpu, max(es, 1e-5), "o", color=col, label=f"{name}: |E_s - 1|")
        ax.semilogy(cpu, 10 ** (floor / 10), "s", color=col, mfc="none", label=f"{name}: sigma_s(88) / peak")
    ax.set(xlabel="CPU s (one flat partition, s + p)", ylabel="error", title="Error against cost (flat plate)")
    ax.legend(fontsize=6)
    below = flagged_legend(fig, loc="lower center", fontsize=6, ncol=2) * 1.2 / fig.get_figheight()
    fig.tight_layout(rect=(0, below, 1, 1))
    save_figure(fig, path)


if __name__ == "__main__":
    cli(validate, __doc__)
