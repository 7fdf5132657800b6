"""Honest capture answers (issue 22): a map fit says when its standard errors cannot be trusted.

Physics and statistics checked, in llvm_ad_mono_polarized on small planes: the convergence test
flags a texel whose last Gauss-Newton step is more than CONVERGENCE_THRESHOLD standard errors (or hit
the step clip), and only that texel and parameter; a fit stopped after 2 Adam iterations with one
Gauss-Newton step gets a NotConvergedWarning (once) and NaN standard errors exactly where
``result.converged`` is False; the bitmap filter is read from the texture itself (nearest returns a
texel's value a quarter texel off its centre, bilinear a blend); bilinear maps of the hyde plugin are
switched to nearest with one BilinearFilterWarning (same fit and errors as nearest maps), those of
other BSDFs give NaN standard errors and one BilinearFilterWarning; unseen texels and texels without a valid standard error are NaN
in ``result.measured``; the scalar trajectory test tells a drift from jitter.
"""
import warnings

import numpy as np
import pytest

import mitsuba as mi

from hyde_bsdf import inverse as inv
from hyde_bsdf.inverse import acquisition as acqm
from hyde_bsdf.inverse.uncertainty import convergence_test, convergence_warnings


pytestmark = pytest.mark.usefixtures("map_variant")     # tests/conftest.py


def _observations(filter_type="nearest", n=2, res=12):
    truth = acqm.example_material("dielectric", n)
    truth["specular_reflectance"] = 1.0
    acq = inv.acquisition.fixed_rig_acquisition("dielectric", facet_angle=50.0, tilts=(0.0, 12.0))
    start = {"alpha": 0.3, "eta": 1.6}
    obs = inv.synthetic_observations(acq, truth, start, res=res, spp=4, spp_ref=32, noise=0.01, seed=2,
                                     filter_type=filter_type)
    return truth, start, obs


def test_convergence_test_flags_large_steps_only():
    """rel = 1 %: steps of 0.5 and 2.9 standard errors pass, 3.5 fails, a clipped step fails, a texel
    without a standard error (NaN) or unseen is not judged here."""
    rel = np.array([[0.01, 0.01], [0.01, 0.01], [np.nan, 0.01], [0.01, 0.01]])
    step = np.array([[0.005, 0.029], [0.035, -0.001], [0.5, 0.0], [0.25, 0.0]])
    seen = np.array([True, True, True, True])
    ok, ratio = convergence_test(step, rel, seen, threshold=3.0, clip=0.25)
    assert ok.tolist() == [[True, True], [False, True], [True, True], [False, True]]
    assert ratio[1, 0] == pytest.approx(3.5) and ratio[0, 1] == pytest.approx(2.9)
    ok2, _ = convergence_test(step, rel, np.array([True, False, True, True]), threshold=3.0)
    assert ok2[1, 0]
    found = convergence_warnings({"alpha": ok[:, 0].reshape(2, 2)}, {"alpha": ratio[:, 0].reshape(2, 2)}, None)
    frac, msg = found["alpha"]
    assert frac == 0.5 and msg.startswith("alpha has not converged in 50 % of the 4 seen texels")
    assert "standard errors are set to NaN" in msg


def test_filter_type_is_read_from_the_texture():
    """The filter is read from the texture; build() switches the hyde plugin's bilinear bitmaps to
    nearest (problem.nearest names them, and the texture then reads as nearest)."""
    import mitsuba as mi

    for filter_type, expected in (("nearest", False), ("bilinear", True)):
        _, start, obs = _observations(filter_type)
        params = mi.traverse(obs[0].scene)
        key = next(k for k in params.keys() if k.endswith("alpha.data"))
        assert inv.maps.filters_bilinearly(params, key, params[key].shape, inv.MAP_PARAMETERS["alpha"][1]) is expected
        problem = inv.maps.MapProblem.build(obs, start, tuple(start))
        assert problem.bilinear == () and problem.nearest == (("alpha", "eta") if expected else ())
        assert not inv.maps.filters_bilinearly(problem.all_params[0], problem.keys[0]["alpha"], problem.shapes["alpha"],
                                          inv.MAP_PARAMETERS["alpha"][1])


def test_stopped_early_warns_once_and_nans_its_standard_errors():
    """Two Adam iterations from constant starts, one Gauss-Newton step and no extra ones: the texels
    are still moving, so their standard errors would understate the error; they must be NaN where
    result.converged is False, finite elsewhere, and the warning comes once per parameter."""
    truth, start, obs = _observations()
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        res = inv.invert_maps(obs, start, fit=tuple(start), iterations=2, progress=False, uncertainty_spp=4,
                              polish=1, extra_polish=0, freeze=False)
    ours = [str(w.message) for w in caught if issubclass(w.category, inv.NotConvergedWarning)]
    assert ours and len(ours) == len(set(ours)) and set(ours) <= set(res.warnings)
    assert len(res.warnings) == len(set(res.warnings))
    for name in start:
        bad = ~res.converged[name]
        assert np.all(np.isnan(res.stderr[name][bad])) and np.all(np.isfinite(res.stderr[name][~bad]))
    assert any((~res.converged[n]).any() for n in start)
    assert any(m.startswith(("alpha has not converged", "eta has not converged")) for m in ours)


def test_bilinear_maps_are_fitted_as_nearest_with_one_warning():
    """A sample whose material changes from texel to texel (references rendered with nearest maps),
    fitted from scenes whose bitmaps filter bilinearly (Mitsuba's default): invert_maps switches the
    fitted bitmaps to nearest with one BilinearFilterWarning, and the fit and its standard errors are
    those of the nearest scenes (equal to 1e-6: the same renders), so their pulls are the nearest
    case's (measured 1.21 alpha / 1.27 eta on the quick svbrdf_index map, 4 x 4 texels)."""
    runs = {}
    for fit_filter in ("nearest", "bilinear"):
        truth, start, _ = _observations()
        acq = inv.acquisition.fixed_rig_acquisition("dielectric", facet_angle=50.0, tilts=(0.0, 12.0))
        obs = inv.synthetic_observations(acq, truth, start, res=12, spp=4, spp_ref=32, noise=0.01, seed=2,
                                         filter_type="nearest", fit_filter_type=fit_filter)
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            res = inv.invert_maps(obs, start, fit=tuple(start), iterations=2, progress=False, uncertainty_spp=4,
                                  polish=1, extra_polish=0, freeze=False)
        runs[fit_filter] = (res, [str(w.message) for w in caught if issubclass(w.category, inv.BilinearFilterWarning)])
    (near, w_near), (bil, w_bil) = runs["nearest"], runs["bilinear"]
    assert w_near == [] and len(w_bil) == 1 and "switched to filter_type nearest" in w_bil[0]
    assert w_bil[0] in bil.warnings and bil.uncertainty.filter_valid
    for n in ("alpha", "eta"):
        np.testing.assert_allclose(bil.final[n], near.final[n], rtol=1e-6)
        np.testing.assert_allclose(bil.stderr[n], near.stderr[n], rtol=1e-6)
    problem = inv.maps.MapProblem.build(obs, {"alpha": 0.3, "eta": 1.6}, ("alpha", "eta"))
    assert problem.bilinear == () and problem.nearest == ()        # the scenes were changed in place


def test_bilinear_maps_of_other_bsdfs_give_nan_standard_errors_and_one_warning():
    """roughconductor's bitmap cannot be swapped (only the hyde plugin takes replace_texture): it stays
    bilinear, its standard errors are NaN, and one BilinearFilterWarning says why."""
    truth = {"alpha": acqm.example_material("dielectric", 2)["alpha"], "eta": 0.2, "k": 3.0,
             "specular_reflectance": 1.0}
    acq = inv.acquisition.fixed_rig_acquisition("metal", facet_angle=50.0, tilts=(0.0, 12.0))
    obs = inv.synthetic_observations(acq, truth, {"alpha": 0.3}, res=12, spp=4, spp_ref=16, noise=0.01, seed=2,
                                     bsdf="roughconductor", filter_type="bilinear")
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        res = inv.invert_maps(obs, {"alpha": 0.3}, fit=("alpha",), iterations=2, progress=False,
                              uncertainty_spp=4, polish=1, extra_polish=0, freeze=False)
    bil = [str(w.message) for w in caught if issubclass(w.category, inv.BilinearFilterWarning)]
    assert len(bil) == 1 and "filter_type" in bil[0] and "set to NaN" in bil[0]
    assert not res.uncertainty.filter_valid and np.all(np.isnan(res.stderr["alpha"]))
    assert np.all(np.isfinite(res.uncertainty.unchecked["alpha"]))


def test_measured_masks_unseen_and_invalid_texels():
    final = {"alpha": np.array([[0.2, 0.3], [0.4, 0.5]])}
    res = inv.MapInversionResult(fitted=("alpha",), final=final, start={"alpha": 0.3}, components="stokes",
                                 seen=np.array([[True, True], [False, True]]))
    res.rel_stderr = {"alpha": np.array([[0.01, np.nan], [0.01, 0.02]])}
    assert res.valid("alpha").tolist() == [[True, False], [False, True]]
    m = res.measured("alpha")
    assert m[0, 0] == 0.2 and m[1, 1] == 0.5 and np.isnan(m[0, 1]) and np.isnan(m[1, 0])


def test_trajectory_convergence_tells_drift_from_jitter():
    rng = np.random.default_rng(3)
    level = 1.5 + 0.002 * rng.standard_normal(20)            # jitter around a level
    assert inv.scalar.trajectory_converged(level, "eta") == (True, "")
    trend = np.linspace(1.2, 1.4, 20) + 0.002 * rng.standard_normal(20)   # still moving
    ok, msg = inv.scalar.trajectory_converged(trend, "eta")
    assert not ok and msg.startswith("eta has not converged: it moved by")
    assert inv.scalar.trajectory_converged(np.linspace(1.5, 1.5005, 20), "eta")[0]   # below the 0.1 % floor
    assert not inv.scalar.trajectory_converged([1.0, 1.1], "eta")[0]


def test_monochrome_message_once_per_run():
    """Mitsuba says 'Monochrome mode enabled' for every rgb hdrfilm loaded in a mono variant; within
    log_once it reaches the logger's appenders once, and other messages pass."""
    from hyde_bsdf.mitsuba.log import log_once

    received = []

    class Record(mi.Appender):
        def append(self, level, text):
            received.append(text)

        def log_progress(self, *args):
            pass

    logger = mi.logger()
    record = Record()
    logger.add_appender(record)
    scene = {"type": "scene", "sensor": {"type": "perspective", "film": {"type": "hdrfilm", "width": 4, "height": 4}}}
    try:
        with log_once():
            for _ in range(3):
                mi.load_dict(scene)
            mi.Log(mi.LogLevel.Warn, "another message")
        mi.load_dict(scene)           # restored: said again outside the block
    finally:
        logger.remove_appender(record)
    texts = " | ".join(received)
    assert texts.count("Monochrome mode enabled") == 2 and "another message" in texts


def test_scene_bitmaps_are_loaded_nearest(tmp_path):
    """A scene whose alpha bitmap has no filter_type (bilinear) is loaded with nearest lookup by
    load_scene_nearest, which names what it changed; a nearest one is left alone."""
    from hyde_bsdf.render.renderer import load_scene_nearest

    mi.Bitmap(np.full((4, 4, 1), 0.3, np.float32)).write(str(tmp_path / "alpha.exr"))
    xml = """<scene version="3.0.0">
    <sensor type="perspective"><film type="hdrfilm"><integer name="width" value="4"/>
        <integer name="height" value="4"/><string name="pixel_format" value="luminance"/></film></sensor>
    <shape type="rectangle"><bsdf type="hyde">
        <texture name="alpha" type="bitmap"><string name="filename" value="alpha.exr"/>
            <boolean name="raw" value="true"/>FILTER</texture>
    </bsdf></shape></scene>"""
    for filt, changed in (("", ["alpha"]), ('<string name="filter_type" value="nearest"/>', [])):
        path = tmp_path / "scene.xml"
        path.write_text(xml.replace("FILTER", filt))
        scene, names = load_scene_nearest(path, ("alpha",))
        assert names == changed
        params = mi.traverse(scene)
        key = inv.observations.map_keys(params, ("alpha",))["alpha"]
        assert not inv.maps.filters_bilinearly(params, key, params[key].shape, inv.MAP_PARAMETERS["alpha"][1])


def _record(rng, t, sigma, offset=0.0):
    """A pixel_records record of one picture: 2 parameters, the S0 component only, residuals of
    standard deviation ``sigma`` (known) plus ``offset`` on texel 1."""
    n = t.size
    r = np.zeros((4, n))
    r[0] = sigma * rng.standard_normal(n) + offset * (t == 1)
    return dict(t=t, J=np.ones((2, 4, n)), r=r, w=np.ones((4, n)), mc_var=np.zeros(4),
                ref_var=np.full(4, sigma ** 2), comps=(0,), obs_weight=1.0, s0_power=1.0)


def test_texel_misfit_tells_a_held_texel_from_noise():
    """Residuals at the noise level give chi2 ~ m (p-values of order 0.1-1); a texel whose residuals
    sit 1 sigma above the noise (held away from its minimum) over 200 values gets p < 1e-10."""
    from hyde_bsdf.inverse.uncertainty import misfit_pvalues, texel_misfit

    rng = np.random.default_rng(5)
    t = np.repeat(np.arange(4), 200)
    chi2, m = texel_misfit([_record(rng, t, 0.01, offset=0.01)], (2, 2))
    assert m.tolist() == [200.0] * 4
    p = misfit_pvalues(chi2, m, 2)
    assert p[1] < 1e-10 and np.all(p[[0, 2, 3]] > 1e-2)
    assert abs(chi2[0] / 198 - 1) < 0.25 and abs(chi2[1] / 198 - 2) < 0.5       # noise 1x, + offset 2x
    # a step that removes texel 1's offset (J = 1 per parameter, d = -offset / 2 each) leaves noise only
    step = np.zeros((4, 2))
    step[1] = -0.005
    chi2_after, _ = texel_misfit([_record(np.random.default_rng(5), t, 0.01, offset=0.01)], (2, 2), step=step)
    assert misfit_pvalues(chi2_after, m, 2)[1] > 1e-2


def test_texel_convergence_catches_texels_the_steps_no_longer_move():
    """Four texels, two parameters, all steps below 1 standard error: texel 0 converged; texel 1 at
    a bound in alpha (pinned); texel 2 with residuals above the noise (p = 1e-5); texel 3 with eta's
    step 5 standard errors and alpha's small.  1-3 are not converged in *both* parameters (the joint
    rule), 0 is; an unseen texel is not judged."""
    from hyde_bsdf.inverse.uncertainty import at_bounds, texel_convergence

    rel = np.full((4, 2), 0.01)
    step = np.full((4, 2), 0.005)
    step[3, 1] = 0.05
    pinned = at_bounds(np.array([[0.3, 1.6], [inv.MAP_PARAMETERS["alpha"][1][0], 1.6], [0.3, 1.6], [0.3, 1.6]]),
                       [inv.MAP_PARAMETERS["alpha"][1], inv.MAP_PARAMETERS["eta"][1]])
    assert pinned.tolist() == [[False, False], [True, False], [False, False], [False, False]]
    p = np.array([0.5, 0.5, 1e-5, 0.5])
    ok, ratio = texel_convergence([step, step], rel, np.ones(4, bool), misfit_p=p, pinned=pinned)
    assert ok.tolist() == [[True, True], [False, False], [False, False], [False, False]]
    assert ratio[3, 1] == pytest.approx(5.0) and ratio[0, 0] == pytest.approx(0.5)
    ok2, _ = texel_convergence([step, step], rel, np.array([True, False, False, False]), misfit_p=p, pinned=pinned)
    assert ok2.all()


def test_stopped_early_keeps_no_standard_error_far_from_the_truth():
    """The quick svbrdf_index stopped-early case (4 x 4 dielectric map, the fixed rig's 2 pictures at
    tilts 0 and 12 deg, 1 % noise, 8 Adam iterations, 2 Gauss-Newton steps, no extra ones): before the
    misfit, bound and joint tests one eta texel 10 standard errors off (its alpha 20 % off, its own
    steps small) kept its standard error; now no texel with a valid standard error is more than 4 of
    them from the truth."""
    truth = acqm.example_material("dielectric", 4)
    truth["specular_reflectance"] = 1.0
    start = {"alpha": 0.3, "eta": 1.6}
    acq = inv.acquisition.fixed_rig_acquisition("dielectric", facet_angle=50.0, tilts=(0.0, 12.0))
    obs = inv.synthetic_observations(acq, truth, start, res=16, spp=4, spp_ref=32, noise=0.01, seed=0)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)      # the NotConvergedWarning is the subject here
        res = inv.invert_maps(obs, start, fit=tuple(start), iterations=8, spp=4, seed=7, progress=False,
                              uncertainty_spp=4, polish=2, extra_polish=0, freeze=False, truth=truth)
    for name in start:
        z = res.pulls(name)
        assert np.all(np.abs(z[np.isfinite(z)]) <= 4.0), (name, z)
        raw = (res.final[name] - truth[name]) / (res.uncertainty.unchecked[name] * res.final[name])
        assert np.nanmax(np.abs(raw)) > 5.0           # the case does hold texels far off
