"""Paper Fig. 4: F00 of the Priest-Germer pBRDF (no shadowing, no diffuse) diverges as
theta_r -> 90 deg while the Hyde pBRDF (V-groove G, Eq. 13) stays bounded.

PEC, rms_slope = 0.3, specular plane (phi = pi), theta_i = 45, 60, 75, 85 deg.
Writes fig4_priest_germer.png and .csv into OUTDIR (default out/validation).
"""
import math
from pathlib import Path

import matplotlib
matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

from hyde_bsdf.validation._common import cli, save_figure, write_csv  # noqa: E402

import hyde_bsdf

THETA_I = (45, 60, 75, 85)


def validate(outdir="out/validation", quick=False):
    out = Path(outdir)
    out.mkdir(parents=True, exist_ok=True)
    tr_deg = np.linspace(0, 89.9, 400 if not quick else 150)
    tr = np.radians(tr_deg)
    rows, checks = [], []
    fig, ax = plt.subplots(figsize=(7, 4.5))
    for k, deg in enumerate(THETA_I):
        ti = math.radians(deg)
        hyde = hyde_bsdf.pbrdf(ti, tr, math.pi, rms_slope=0.3, pec=True, diffuse=False)[..., 0, 0]
        pg = hyde_bsdf.pbrdf(ti, tr, math.pi, rms_slope=0.3, pec=True, shadowing="none",
                             diffuse=False)[..., 0, 0]
        c = f"C{k}"
        ax.semilogy(tr_deg, pg, "--", color=c, label=f"Priest-Germer, θi={deg}°")
        ax.semilogy(tr_deg, hyde, "-", color=c, label=f"Eq. 13 (V-groove), θi={deg}°")
        rows += [(deg, a, b, h) for a, b, h in zip(tr_deg, pg, hyde)]
        # the grazing behaviour: PG grows like 1/cos(theta_r); Eq. 13 tends to a finite limit
        grazing = math.pi / 2 - np.array([1e-5, 1e-8])
        h = hyde_bsdf.pbrdf(ti, grazing, math.pi, rms_slope=0.3, pec=True, diffuse=False)[..., 0, 0]
        p = hyde_bsdf.pbrdf(ti, grazing, math.pi, rms_slope=0.3, pec=True, shadowing="none",
                            diffuse=False)[..., 0, 0]
        checks.append(dict(name=f"Fig4 Eq.13 bounded at grazing, θi={deg}°: relative change 1e-5 -> 1e-8 rad",
                           value=float(abs(h[1] - h[0]) / h[0]), tolerance=1e-3,
                           passed=bool(abs(h[1] - h[0]) / h[0] < 1e-3)))
        checks.append(dict(name=f"Fig4 Priest-Germer diverges, θi={deg}°: F00 ratio 1e-8 vs 1e-5 rad from grazing",
                           value=float(p[1] / p[0]), tolerance=">100", passed=bool(p[1] / p[0] > 100)))
    ax.set_xlabel("θr (deg), specular plane φ = π")
    ax.set_ylabel("F00 (1/sr)")
    ax.set_title("Fig. 4: PEC, √2σh/ℓ = 0.3")
    ax.set_ylim(1e-3, 1e3)
    ax.legend(fontsize=7, ncol=2)
    fig.tight_layout()
    save_figure(fig, out / "fig4_priest_germer.png")
    write_csv(out / "fig4_priest_germer.csv", ["theta_i_deg", "theta_r_deg", "F00_priest_germer", "F00_hyde_eq13"], rows)
    return checks


if __name__ == "__main__":
    cli(validate, __doc__)
