"""The comparison the paper could not make: the model's polarisation against exact EM (issue 11, part 3).

1-D Gaussian surfaces (ell = 5 lambda) at the slopes of the paper's Figs. 8-9: Infragold
(eta = 0.285 - 7.3523 j, rms slope 0.44) and flame-sprayed aluminium (1.226 - 10.413 j,
rms slope 0.43), and a PEC on the Infragold surface (same seed); theta_i = 10-75 deg,
both polarisations on the same realisation.  The MoM's in-plane Mueller elements
(:attr:`hyde_bsdf.mom.MoMResult.mueller`) against the pBRDF's 1-D reduction with the same
index (:func:`hyde_bsdf.mom.model1d.mueller_sigma`: facet Fresnel r_s, r_p at the local
incidence angle beta = (theta_i + theta_r)/2, single bounce, V-groove shadowing, plus the
unpolarised diffuse term of Eq. 16 in M00): M00 in absolute dB over the lobe (where the
model's M00 is >= 10 % of its peak), M01/M00, M22/M00, M23/M00 as absolute differences
over the lobe.  Also reflected + absorbed = 1 within 1 % per polarisation (the lossy
energy check; full mode 10-75 deg: <= 0.0087.  The quick mode's 4 partitions of 100
lambda check 10-60 deg: at 75 deg p-polarised waves launched along the metal by the
short partitions' truncated ends are absorbed under the window and the sum comes out
up to 6 % high -- reported there, a limitation of Eq. 22's windowed partitions).

What the numbers say (full mode: 40 partitions of 150 lambda, 10 pts/lambda, seed 11;
mom_mueller_1d_table.csv; Infragold and flame-sprayed Al behave alike):

* M00: the model is within 0.9-1.0 dB rms of the MoM over the lobe for theta_i = 10-60
  deg, 2.0 dB at 75 deg, where the MoM's forward lobe is ~2 dB lower than the model's
  and its backscatter side (theta_r < -40 deg) falls far below the model's Lambertian
  diffuse term.
* M01/M00: the facet Fresnel term makes it ~0.01-0.03; the MoM agrees over the lobe
  (rms difference 0.05-0.08 at 10-60 deg, mostly speckle), but on the backscatter side at
  45-75 deg the MoM has M01/M00 = -0.4 to -0.9: p is scattered back far more than s,
  which single-bounce facets cannot produce.
* M22/M00: near specular the model's -0.9 matches the MoM.  Where the model hands the
  light to its diffuse term -- the backscatter side, grazing incidence -- the model's
  M22/M00 is diluted towards 0 (the diffuse term is unpolarised), while the MoM stays at
  -0.75 to -1 at 10-45 deg: the off-lobe light of these surfaces is *not* depolarised.
  On the forward wing at 45-75 deg the opposite: the MoM's M22/M00 rises to -0.5...-0.1
  while the model stays near -0.9, the signature of multiple scattering (two bounces
  with different local angles retard and mix s and p), which the single-bounce facet
  Fresnel misses.  rms differences over the lobe 0.07 (10 deg) to 0.21 (60 deg).
* M23/M00: the model's retardance grows smoothly to -1 at grazing forward scattering;
  the MoM follows its trend at 45-75 deg but reaches only about -0.5, and has a
  structure of opposite sign on the backscatter side at 75 deg (rms difference 0.07-0.18).
* PEC on the same surface: the model predicts sigma_s = sigma_p (M01 = 0); the MoM's s
  and p split on the backscatter side and at 75 deg (the plotted sigma_s, sigma_p), and
  its M22/M00 leaves -1 in the same places as for the metals -- so these departures
  come from multiple scattering and diffraction by the surface, not from the index.

Writes, per material, mom_mueller_1d_<material>.png and .csv (curves), and
mom_mueller_1d_table.csv.
"""
import math
import warnings
from pathlib import Path

import numpy as np

from hyde_bsdf.validation._common import atlas_checks, cli, plot_flagged, save_figure, valid_m00, write_csv

ELL = 5.0
THETA_I = [10.0, 30.0, 45.0, 60.0, 75.0]
THETA_R = np.arange(-89.0, 89.01, 1.0)
CASES = [("infragold", "Infragold", 0.285, 7.3523, 0.44), ("flame_sprayed_al", "flame-sprayed Al", 1.226, 10.413, 0.43),
         ("pec", "PEC (Infragold surface)", None, None, 0.44)]
LOBE = 0.1
RATIOS = ("M01/M00", "M22/M00", "M23/M00")


def theta_i(quick):
    """10-75 deg; the quick mode keeps the three angles the figures show."""
    return [10.0, 45.0, 75.0] if quick else THETA_I


def run(case, quick):
    from hyde_bsdf import mom

    _, _, n, k, slope = case
    parts, plen = (4, 100.0) if quick else (40, 150.0)
    ex = mom.process_pool(2)
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", mom.MoMAccuracyWarning)  # recorded in res.warnings, reported below
            res = mom.scatter(plen * parts, parts, slope * ELL / math.sqrt(2.0), ELL, theta_i(quick), THETA_R,
                              pts_per_wl=10, seed=11, executor=ex, polarization=("s", "p"), n=n, k=k,
                              progress=False)
    finally:
        ex.shutdown()
    return res


def model(case, ti):
    from hyde_bsdf.mom import model1d

    _, _, n, k, slope = case
    return model1d.mueller_sigma(np.radians(ti)[:, None], np.radians(THETA_R), slope, n, 0.0 if k is None else k)


def compare(res, mod):
    """Per theta_i: lobe mask, M00 dB rms/max, and |difference| rms/max of each ratio over the lobe."""
    rows = []
    for i, t in enumerate(np.round(res.theta_i_deg, 6)):
        m00 = mod["M00"][i]
        lobe = m00 >= LOBE * m00.max()
        db = 10 * np.log10(np.maximum(res.mueller["M00"][i][lobe], 1e-30) / m00[lobe])
        row = [t, int(lobe.sum()), float(np.sqrt(np.mean(db**2))), float(np.max(np.abs(db)))]
        for key in RATIOS:
            d = res.mueller_normalised[key][i][lobe] - (mod[key.split("/")[0]][i] / m00)[lobe]
            row += [float(np.sqrt(np.mean(d**2))), float(np.max(np.abs(d)))]
        row += [float(res.energy_s[i]), float(res.energy_p[i]), float(res.absorbed_s[i]), float(res.absorbed_p[i])]
        rows.append(row)
    return rows


def figure(case, res, mod, path):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    stem, title, n, _, slope = case
    fig, axes = plt.subplots(2, 2, figsize=(10, 7))
    colours = {10.0: "C0", 45.0: "C1", 75.0: "C3"}
    for t, c in colours.items():
        i = list(np.round(res.theta_i_deg, 6)).index(t)
        m00 = mod["M00"][i]
        ok = valid_m00(res)[i]
        ax = axes[0, 0]
        if n is None:
            plot_flagged(ax, THETA_R, 10 * np.log10(np.maximum(res.sigma_s[i], 1e-6)), res.valid_s[i], res.floor_reason,
                         color=c, lw=1, label=f"MoM s, {t:g}")
            plot_flagged(ax, THETA_R, 10 * np.log10(np.maximum(res.sigma_p[i], 1e-6)), res.valid_p[i], res.floor_reason,
                         color=c, lw=1, ls=":", label=f"MoM p, {t:g}")
        else:
            plot_flagged(ax, THETA_R, 10 * np.log10(np.maximum(res.mueller["M00"][i], 1e-6)), ok, res.floor_reason,
                         color=c, lw=1, label=f"MoM, {t:g}")
        ax.plot(THETA_R, 10 * np.log10(np.maximum(m00, 1e-6)), color=c, ls="--", lw=1, label=f"model, {t:g}")
        for ax, key in zip((axes[0, 1], axes[1, 0], axes[1, 1]), RATIOS):
            r, se = res.mueller_normalised[key][i], res.mueller_normalised_std_error[key][i]
            plot_flagged(ax, THETA_R, r, ok, color=c, lw=1)
            ax.fill_between(THETA_R, r - se, r + se, where=ok, color=c, alpha=0.2, lw=0)
            ax.plot(THETA_R, mod[key.split("/")[0]][i] / np.where(m00 > 0, m00, np.nan), color=c, ls="--", lw=1)
    axes[0, 0].set(ylim=(-30, 15), ylabel="dB (sigma units)",
                   title="M00 (PEC: sigma_s, sigma_p; model: s = p)" if n is None else "M00")
    axes[0, 0].legend(fontsize=5, ncol=2)
    for ax, key in zip((axes[0, 1], axes[1, 0], axes[1, 1]), RATIOS):
        ax.set(title=key + " (MoM solid with +-1 s.e., grey x flagged; model dashed)", ylim=(-1.05, 1.05))
    for ax in axes[1]:
        ax.set_xlabel("theta_r (deg, + = specular side)")
    fig.suptitle(f"MoM vs the 1-D pBRDF, {title}, rms slope {slope}, ell = {ELL:g} lambda, "
                 f"{res.params['partitions']} partitions", fontsize=9)
    # the margins tight_layout chose for these labels, fixed: it measured every tick label again (~0.1 CPU s)
    fig.subplots_adjust(left=0.075, right=0.985, bottom=0.084, top=0.907, wspace=0.17, hspace=0.232)
    save_figure(fig, path)


def validate(outdir="out/validation", quick=False):
    out = Path(outdir)
    out.mkdir(parents=True, exist_ok=True)
    table, checks = [], []
    paired = {}
    for case in CASES:
        stem, title, n, k, slope = case
        res = run(case, quick)
        mod = model(case, theta_i(quick))
        figure(case, res, mod, out / f"mom_mueller_1d_{stem}.png")
        curves = []
        m00_ok = valid_m00(res)
        for i, t in enumerate(np.round(res.theta_i_deg, 6)):
            for j, tr in enumerate(THETA_R):
                row = [t, tr, res.mueller["M00"][i, j], res.mueller_std_error["M00"][i, j]]
                for key in RATIOS:
                    row += [res.mueller_normalised[key][i, j], res.mueller_normalised_std_error[key][i, j]]
                m00 = mod["M00"][i, j]
                row += [m00] + [mod[key.split("/")[0]][i, j] / m00 if m00 > 0 else float("nan") for key in RATIOS]
                row += [res.sigma_s[i, j], res.sigma_p[i, j], int(res.valid_s[i, j]), int(res.valid_p[i, j]),
                        int(m00_ok[i, j])]
                curves.append(row)
        write_csv(out / f"mom_mueller_1d_{stem}.csv",
                  ["theta_i_deg", "theta_r_deg", "mom_M00", "mom_M00_se", "mom_M01/M00", "se", "mom_M22/M00", "se",
                   "mom_M23/M00", "se", "model_M00", "model_M01/M00", "model_M22/M00", "model_M23/M00",
                   "mom_sigma_s", "mom_sigma_p", "valid_s", "valid_p", "valid_M00"], curves)
        rows = compare(res, mod)
        table += [[title] + r for r in rows]
        top = 60.0 if quick else 75.0
        energy = max(max(abs(r[-4] - 1), abs(r[-3] - 1)) for r in rows if r[0] <= top)
        tol = 0.03 if quick else 0.01  # quick: 4 partitions of 100 lambda leave ~2 % sample noise (PEC too)
        checks.append(dict(name=f"MoM {title}: max |reflected + absorbed - 1| over s, p, theta_i 10-{top:g} deg",
                           value=f"{energy:.4f}", tolerance=tol, passed=energy <= tol))
        # at 75 deg the partitions' truncated ends launch p-polarised waves along the metal whose absorption
        # under the window is counted (as on the flat plate at 80 deg): reported, a known limitation
        graze = [r for r in rows if r[0] > top]
        if graze:
            checks.append(dict(name=f"MoM {title}: reflected + absorbed at 75 deg (s, p; edge waves of the "
                                    "truncated partitions enter the absorbed power)",
                               value=f"{graze[0][-4]:.4f}, {graze[0][-3]:.4f}", tolerance="reported", passed=True))
        for r in rows:
            checks.append(dict(name=f"MoM vs 1-D model {title}, theta_i = {r[0]:g} deg: M00 rms dB over the lobe; "
                                    "rms |diff| M01/M00, M22/M00, M23/M00",
                               value=f"{r[2]:.2f} dB; {r[4]:.3f}, {r[6]:.3f}, {r[8]:.3f}", tolerance="reported",
                               passed=bool(np.all(np.isfinite(r[2:10])))))
        paired[stem] = [(r[-4], r[-3]) for r in rows]
    # the absorbed power's accounting on its own: the Infragold and PEC runs share the surface and the
    # window, so their sample noise cancels in the difference of reflected + absorbed
    diff = max(max(abs(a[0] - b[0]), abs(a[1] - b[1])) for a, b in zip(paired["infragold"], paired["pec"]))
    checks.insert(0, dict(name="MoM Infragold minus PEC on the same surface: max |difference of reflected + absorbed|",
                          value=f"{diff:.4f}", tolerance="reported", passed=bool(np.isfinite(diff))))
    for stem, title, n, k, slope in CASES:
        checks += atlas_checks("MoM vs 1-D model", theta_i(quick), slope, slope * ELL / math.sqrt(2.0), [(title, n, k)])
    write_csv(out / "mom_mueller_1d_table.csv",
              ["material", "theta_i_deg", "lobe_points", "M00_rms_dB", "M00_max_dB", "M01/M00_rms", "M01/M00_max",
               "M22/M00_rms", "M22/M00_max", "M23/M00_rms", "M23/M00_max", "energy_s", "energy_p", "absorbed_s",
               "absorbed_p"], table)
    return checks


if __name__ == "__main__":
    cli(validate, __doc__)
