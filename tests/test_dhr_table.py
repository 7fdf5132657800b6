"""The DHR tables shipped in hyde_bsdf/data/ (model/dhr.py, "Shipped as data").

Physics checked: the shipped rho^{s,PEC} (Eqs. 14-16) is the slope-space quadrature of each
shadowing record at a sample of nodes (the corners, the grazing end and 60 nodes drawn with a
fixed seed per record; the same rule and nodes, so to 1e-12); rho_avg is the cosine-weighted mean
of rho; the plugin's texture is 1 - rho resampled from the shipped table (a sample of 4000 texels,
to float32 rounding); and loading builds nothing, writes nothing and imports no SciPy.
About 3 s (the quadrature of ~200 nodes, a fresh interpreter).
"""
import math
import subprocess
import sys

import numpy as np
import pytest

from hyde_bsdf.model import dhr
from hyde_bsdf.model.terms import SHADOWING

CORNERS = ((0, 0), (0, -1), (-1, 0), (-1, -1), (-3, 2), (-9, 30), (76, 60), (140, 10))


@pytest.mark.parametrize("shadowing", SHADOWING)
def test_shipped_nodes_are_the_quadrature(shadowing):
    table = dhr.load_table(shadowing)
    x, log_slope = dhr._grid()
    np.testing.assert_array_equal(table.x, x)               # the grid the code defines
    np.testing.assert_array_equal(table.log_slope, log_slope)
    assert table.rho.shape == (dhr.TABLE_THETA_POINTS, dhr.TABLE_SLOPE_POINTS) and table.rho.dtype == np.float64
    drawn = np.random.default_rng(7).choice(table.rho.size, 60, replace=False)
    i = np.concatenate([[a % x.size for a, _ in CORNERS], drawn // log_slope.size])
    j = np.concatenate([[b % log_slope.size for _, b in CORNERS], drawn % log_slope.size])
    from hyde_bsdf.model.terms import shadowing_term
    fresh = dhr.dhr_quadrature(table.theta[i], np.exp(log_slope[j]), shadowing, *shadowing_term(shadowing).dhr_order)
    np.testing.assert_allclose(table.rho[i, j], fresh, rtol=0, atol=1e-12)
    np.testing.assert_allclose(table.rho_avg, dhr._rho_average(x, table.rho), rtol=0, atol=1e-12)


@pytest.mark.parametrize("shadowing", SHADOWING)
def test_shipped_texture_is_the_table_resampled(shadowing):
    """The plugin's texture: 1 - rho on 1025 x (192 per decade) nodes through the table's spline."""
    table, tex = dhr.load_table(shadowing), dhr.load_texture(shadowing)
    assert (tex.log_lo, tex.log_hi) == (table.log_slope[0], table.log_slope[-1])
    nt, ns = tex.one_minus.shape
    assert nt == dhr.TEXTURE_X_POINTS and tex.one_minus.dtype == np.float32
    assert ns == round((tex.log_hi - tex.log_lo) / math.log(10) * dhr.TEXTURE_SLOPE_PER_DECADE) + 1
    rng = np.random.default_rng(3)
    i, j = np.sort(rng.choice(nt, 80, replace=False)), np.sort(rng.choice(ns, 50, replace=False))
    x, ls = np.linspace(0.0, 1.0, nt)[i], np.linspace(tex.log_lo, tex.log_hi, ns)[j]
    ref = (1.0 - table.on_grid(x, ls)).astype(np.float32)
    np.testing.assert_allclose(tex.one_minus[np.ix_(i, j)], ref, rtol=2.0 ** -23, atol=1e-12)
    ref_avg = (1.0 - table.average(np.exp(ls))).astype(np.float32)
    np.testing.assert_allclose(tex.one_minus_avg[j], ref_avg, rtol=2.0 ** -23, atol=1e-12)


def test_texture_encoding_is_exact():
    a = np.random.default_rng(1).random((33, 5)).astype(np.float32)
    a[0, 0], a[1, 1] = 0.0, np.float32(1e-30)
    np.testing.assert_array_equal(dhr.decode_texture_values(dhr.encode_texture_values(a)), a)


def test_loading_builds_nothing_writes_nothing_and_needs_no_scipy(tmp_path):
    """A fresh interpreter with an empty home folder: both tables load, SciPy stays unimported, the
    home folder stays empty."""
    code = ("import sys; from hyde_bsdf.model import dhr; dhr.build_table = None\n"
            "for s in ('vgroove', 'smith', 'none'): dhr.load_table(s); dhr.load_texture(s)\n"
            "assert not [m for m in sys.modules if m.startswith('scipy')], 'SciPy imported'\n")
    env = {"HOME": str(tmp_path), "PATH": "/usr/bin:/bin"}
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    assert list(tmp_path.iterdir()) == []
