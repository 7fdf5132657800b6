"""The MoM plots mark the angles the result flags (issue 25, item 2: "mark the affected angles in the result and the
plots, with the reason").

``hyde_bsdf/validation/_common.plot_flagged`` is the one helper every MoM plot uses: the curve is drawn where the result is
reported valid and broken at the flagged angles, whose values are drawn grey with crosses and carry one legend
entry with ``MoMResult.floor_reason``.  Checked on a fixed pattern (no solve) and on a real flat-plate result, where
the flagged angles are exactly ``~MoMResult.valid_s``.
"""
import warnings

import matplotlib
import numpy as np
import pytest

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

from hyde_bsdf.validation._common import (FLAGGED_PREFIX, FLAGGED_STYLE, flagged_legend,  # noqa: E402
                                         legend_entries, plot_flagged, valid_m00)

from hyde_bsdf import mom  # noqa: E402


def _drawn_x(line):
    x, y = (np.asarray(v, float) for v in line.get_data())
    return x[np.isfinite(y)]


def test_plot_flagged_greys_exactly_the_flagged_angles():
    """A fixed pattern of 30 angles (isolated and runs of flagged ones, both ends): the coloured line holds exactly
    the valid angles, the grey line exactly the flagged ones, with the reason in its legend entry -- once per axes."""
    x = np.arange(60.0, 90.0)
    y = -0.5 * (x - 60.0)
    valid = np.ones(x.size, bool)
    valid[[0, 7, 15, 16, 17, 27, 28, 29]] = False
    fig, ax = plt.subplots()
    good, bad = plot_flagged(ax, x, y, valid, "below the floor (L = 4 w)", color="C0", label="MoM s")
    np.testing.assert_array_equal(_drawn_x(good), x[valid])
    np.testing.assert_array_equal(_drawn_x(bad), x[~valid])
    np.testing.assert_array_equal(np.asarray(bad.get_ydata(), float)[~valid], y[~valid])
    assert bad.get_color() == FLAGGED_STYLE["color"] and bad.get_marker() == "x" and good.get_color() == "C0"
    assert bad.get_label().startswith(FLAGGED_PREFIX) and "below the floor (L = 4 w)" in bad.get_label()
    _, again = plot_flagged(ax, x, y, valid, "below the floor (L = 4 w)", ls="--", color="C1", label="MoM p")
    labels = ax.get_legend_handles_labels()[1]
    assert labels.count(bad.get_label()) == 1 and not again.get_label().startswith(FLAGGED_PREFIX)
    assert legend_entries([ax], False)[1] == ["MoM s", "MoM p"]
    assert flagged_legend(fig) and len(fig.legends) == 1
    # nothing flagged: no grey points and no legend entry
    fig2, ax2 = plt.subplots()
    _, none = plot_flagged(ax2, x, y, np.ones(x.size, bool), "reason", label="all valid")
    assert _drawn_x(none).size == 0 and not flagged_legend(ax2)
    plt.close(fig)
    plt.close(fig2)


@pytest.fixture(scope="module")
def flat_plate():
    """Flat PEC, 80 deg, w = 37.5 lambda on 4 w, beam, s and p, theta_r 60-89.75 deg (0.1 s)."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", mom.MoMAccuracyWarning)
        return mom.scatter(150.0, 1, 0.0, 5.0, [80.0], np.arange(60.0, 89.76, 0.25), pts_per_wl=10,
                           executor=mom.SerialExecutor(), taper_width_wl=37.5, polarization=("s", "p"),
                           solver="fast", incidence="beam", progress=False)


def test_plot_flagged_on_a_mom_result(flat_plate):
    """On a real result the grey points are the angles ``valid_s`` flags (some, not all: the lobe is valid, the
    truncated partition's floor and the grazing zone are not) and the legend carries ``floor_reason``."""
    res = flat_plate
    tr, valid = res.theta_r_deg, res.valid_s[0]
    assert 20 <= valid.sum() and 20 <= (~valid).sum()
    fig, ax = plt.subplots()
    _, bad = plot_flagged(ax, tr, 10 * np.log10(res.sigma_s[0]), valid, res.floor_reason, label="MoM s")
    np.testing.assert_array_equal(_drawn_x(bad), tr[~valid])
    assert res.floor_reason.split(";")[0] in bad.get_label().replace("\n", " ")
    plt.close(fig)


def test_valid_m00_adds_the_two_floors(flat_plate):
    """M00 = (sigma_s + sigma_p) / 2 is valid where it is >= 20 x the mean floor: on the flat plate's lobe wherever
    both polarisations are, never in the grazing zone (floor inf)."""
    res = flat_plate
    ok = valid_m00(res)
    assert ok.shape == res.valid_s.shape
    assert np.all(ok[res.valid_s & res.valid_p])
    assert not np.any(ok[np.isinf(res.floor_s) | np.isinf(res.floor_p)])


def _flat(theta_i, w, factor, incidence, theta_r):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", mom.MoMAccuracyWarning)
        return mom.scatter(factor * w, 1, 0.0, 5.0, [theta_i], theta_r, pts_per_wl=10, executor=mom.SerialExecutor(),
                           taper_width_wl=w, polarization=("s", "p"), solver="fast", incidence=incidence,
                           progress=False)


def test_windowed_current_obliquity_is_flagged_in_s():
    """Flat PEC, 83 deg, w = 37.5 lambda on 6 w, windowed current: its s radiates the window's spectrum with the
    current's obliquity cos^2 ti where the reflected beam has cos^2 theta_r -- 7.3 dB above the analytic result at
    86-89 deg, and reported valid there before the floor counted it.  Now every s reported valid at 86-89 deg is
    within 3 dB of the analytic reflected beam, and the excess angles are flagged; p (no such bias) stays valid."""
    from hyde_bsdf.validation.mom_forward_grazing import beam_reference

    tr = np.arange(86.0, 89.01, 0.25)
    res = _flat(83.0, 37.5, 6, "window", tr)
    ref = beam_reference(83.0, 37.5, tr)
    err_s = 10 * np.log10(res.sigma_s[0] / ref)
    assert err_s.max() > 6.0                       # the bias is there ...
    assert np.all(np.abs(err_s[res.valid_s[0]]) <= 3.0) and not res.valid_s[0][err_s > 3.0].any()  # ... and flagged
    assert res.valid_p[0].sum() >= 5 and np.all(np.abs(10 * np.log10(res.sigma_p[0] / ref))[res.valid_p[0]] <= 1.0)
    assert "obliquity" in res.floor_reason


def test_grazing_zone_is_the_partitions_cut_of_the_current():
    """Flat PEC, beam, 85 deg, w = 50 lambda on 4 w: in p the MoM's departure from the infinite plane at theta_r =
    86-89.75 deg (-0.7 to -4.2 dB) is the infinite-plane current cut to the partition, to 0.05 dB (computed
    independently by ``truncated_plane_db``): the grazing zone's cause, named in ``floor_reason``."""
    from hyde_bsdf.validation.mom_forward_grazing import beam_reference, truncated_plane_db

    tr = np.arange(86.0, 89.76, 0.25)
    res = _flat(85.0, 50.0, 4, "beam", tr)
    dev = 10 * np.log10(res.sigma_p[0] / beam_reference(85.0, 50.0, tr))
    assert dev.min() < -3.5
    np.testing.assert_allclose(dev, truncated_plane_db(85.0, 50.0, 200.0, tr, "p"), atol=0.05)
    assert not res.valid_p[0][-4:].any() and "cut of the current's tail" in res.floor_reason
