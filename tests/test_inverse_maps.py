"""Texture-valued (SVBRDF) inverse rendering (hyde_bsdf.inverse.invert_maps) on tiny problems.

Physics and behaviour checked, in llvm_ad_mono_polarized with the ``stokes`` integrator around
``path``: a Beckmann alpha map of 8 x 8 texels on a plane, seen by 2 cameras under 2 point lights
(one per scene), is recovered from a constant start (per-texel error falls from ~40 % to a few
per cent); the UV-coverage pass finds exactly the texels whose parameters the rendering depends on
(the gradient is non-zero there and zero elsewhere); the smoothness regulariser has its documented
values and flattens the map; input errors are one-line ValueErrors naming the parameter.
"""
import numpy as np
import pytest

import drjit as dr
import mitsuba as mi

from hyde_bsdf import inverse as inv
from hyde_bsdf.inverse.observations import _obs_mask

N, RES = 8, 32
BSDF = "hyde"     # alpha texture: Beckmann alpha, key alpha.data (as roughconductor)


@pytest.fixture(scope="module")
def problem():
    previous = mi.variant()
    inv.prepare(inv.observations.MAP_VARIANT)
    truth = inv.observations.example_maps(N)
    obs = []
    for light in range(2):
        scene = mi.load_dict(inv.observations.plane_scene_dict(truth, bsdf=BSDF, light=light, res=RES, views=(0.0, 180.0)))
        obs.append(inv.Observation(scene, inv.observations.render_stokes_np(scene, 0, 64, seed=0)))
    yield truth, obs
    if previous is not None and previous != mi.variant():
        mi.set_variant(previous)


def test_alpha_map_recovered_from_two_views(problem):
    truth, obs = problem
    res = inv.invert_maps(obs, {"alpha": 0.3}, iterations=20, spp=4, seed=1, truth={"alpha": truth},
                          progress=False)
    assert res.seen.all()                      # the whole plane is in both views
    first, last = res.history[0], res.history[-1]
    assert first["alpha_median_error"] > 0.25 and first["alpha_p90_error"] > 0.5   # the constant start
    err = res.texel_errors("alpha")
    assert np.median(err) < 0.03 and np.percentile(err, 90) < 0.10
    assert last["data_loss"] < 0.1 * first["data_loss"]
    assert res.final["alpha"].shape == (N, N) and len(res.history) == 20


def test_coverage_matches_gradient_support(problem):
    """A view that sees one half of the plane: coverage > 0 exactly where dL/dalpha != 0."""
    truth, _ = problem
    d = inv.observations.plane_scene_dict(truth, bsdf=BSDF, light=0, res=RES, views=(0.0,))
    d["sensor"]["view0"]["to_world"] = mi.ScalarTransform4f().look_at(origin=[0.6, 0, 3], target=[0.6, 0, 0],
                                                                       up=[0, 1, 0])
    d["sensor"]["view0"]["fov"] = 25
    scene = mi.load_dict(d)
    o = inv.Observation(scene, inv.observations.render_stokes_np(scene, 0, 16, seed=0))
    cover = inv.observations.texel_coverage(o, (N, N))
    assert 16 < (cover > 0).sum() < N * N and (cover[:, :3] == 0).all() and (cover[2:6, 4:] > 0).all()
    params = mi.traverse(scene)
    x = mi.TensorXf(np.full((N, N, 1), 0.4, np.float32))
    dr.enable_grad(x)
    params["plane.bsdf.alpha.data"] = x
    params.update()
    loss = inv.StokesLoss(o.reference, mask=_obs_mask(o))(inv.observations.render_stokes(scene, 0, 4, 3, params=params))
    dr.backward(loss)
    g = np.asarray(dr.grad(x))[..., 0]
    # rows along v, columns along u: the nearest-neighbour lookup and the coverage bin alike
    assert ((g != 0) == (cover > 0)).all()


def test_smoothness_values():
    """tv: a unit step across a 4 x 4 map costs (4 pairs of height 1) / (24 pairs); l2 the same
    with d^2; a constant map costs 0."""
    step = np.zeros((4, 4, 1), np.float32)
    step[:, 2:] = 1.0
    tv = inv.loss.smoothness(mi.TensorXf(step), "tv", eps=1e-6)
    l2 = inv.loss.smoothness(mi.TensorXf(2 * step), "l2")
    assert float(np.asarray(tv).ravel()[0]) == pytest.approx(4 / 24, rel=1e-4)
    assert float(np.asarray(l2).ravel()[0]) == pytest.approx(4 * 4 / 24, rel=1e-6)
    assert float(np.asarray(inv.loss.smoothness(mi.TensorXf(np.ones((4, 4, 1), np.float32)))).ravel()[0]) == 0.0
    with pytest.raises(ValueError, match="regularizer"):
        inv.loss.smoothness(mi.TensorXf(step), "tikhonov")


def test_mask_limits_the_seen_texels(problem):
    """A mask keeping only the left half of the first view (each view sees the whole plane)
    leaves the texels seen there: fewer than all, and a subset of the unmasked coverage."""
    truth, obs = problem
    masked = []
    for o in obs:
        m = inv.loss.interior_mask(o.reference[0])
        m[:, RES // 2:] = False
        masked.append(inv.Observation(o.scene, o.reference, mask=m, weight=0.5))
    full = sum(inv.observations.texel_coverage(o, (N, N)) for o in obs) > 0
    part = sum(inv.observations.texel_coverage(o, (N, N)) for o in masked) > 0
    assert part.sum() < full.sum() and not (part & ~full).any() and part.sum() >= N * N // 4
    res = inv.invert_maps(masked, {"alpha": 0.3}, iterations=2, spp=4, seed=1, progress=False)
    assert (res.seen == part).all()


def test_regulariser_flattens(problem):
    """l2 at weight 10: the map's mean |d alpha| between neighbours ends well below the truth's
    (measured over 24 iterations: 0.63 of the truth's; the unregularised fit: 1.03; weight 0.1:
    1.02), while the regulariser starts at 0 for the constant start map."""
    truth, obs = problem
    smooth = inv.invert_maps(obs, {"alpha": 0.3}, iterations=16, spp=4, seed=1, progress=False,
                             regularizer="l2", weight=10.0)
    flat = float(np.abs(np.diff(smooth.final["alpha"], axis=1)).mean())
    flat_truth = float(np.abs(np.diff(truth, axis=1)).mean())
    assert smooth.history[0]["regularizer"] == 0.0
    assert smooth.history[-1]["regularizer"] > 0.0
    assert flat < 0.8 * flat_truth


def test_input_errors_name_the_parameter(problem):
    truth, obs = problem
    o = obs[0]
    with pytest.raises(ValueError, match="reference is 10x4 pixels but sensor 0's film is 64x32"):
        inv.invert_maps([inv.Observation(o.scene, np.zeros((4, 4, 10)))], {"alpha": 0.3}, iterations=1)
    bad = o.reference.copy()
    bad[0, 3, 3] = np.nan
    with pytest.raises(ValueError, match="NaN"):
        inv.invert_maps([inv.Observation(o.scene, bad)], {"alpha": 0.3}, iterations=1)
    # issue 15: a reference scaled by 1e30 overflowed the float32 loss (a drjit.backward traceback)
    with pytest.raises(ValueError, match=r"peak \|S0\| = .*e\+\d\d, outside the accepted range \[1e-10, 1e\+10\]"):
        inv.invert_maps([inv.Observation(o.scene, o.reference * 1e30)], {"alpha": 0.3}, iterations=1)
    with pytest.raises(FloatingPointError, match="gradient of alpha became NaN or infinite at iteration 3"):
        inv.scalar.check_gradients({"alpha": mi.Float([1.0, float("nan")])}, 3)
    with pytest.raises(ValueError, match="missing 'alpha'"):
        inv.invert_maps(obs, {"eta": 1.5}, iterations=1)
    with pytest.raises(ValueError, match="regularizer"):
        inv.invert_maps(obs, {"alpha": 0.3}, iterations=1, regularizer="tikhonov")
    with pytest.raises(ValueError, match="fit: unknown parameter 'sigma'"):
        inv.invert_maps(obs, {"alpha": 0.3}, fit=("sigma",), iterations=1)
    with pytest.raises(ValueError, match=r"start\['alpha'\] must be a number or an array"):
        inv.invert_maps(obs, {"alpha": np.ones((3, 3))}, iterations=1)
    assert inv.observations.map_keys(mi.traverse(o.scene), ("alpha", "eta", "k")) == {
        "alpha": "plane.bsdf.alpha.data", "eta": "plane.bsdf.eta.value", "k": "plane.bsdf.k.value"}


def test_frozen_step_equals_unfrozen(problem):
    """dr.freeze (the default) replays the recorded step: the same losses and maps as re-tracing
    every iteration (measured max |d alpha| 5e-8), after a coverage pass that used NumPy input."""
    truth, obs = problem
    runs = [inv.invert_maps(obs, {"alpha": 0.3}, iterations=4, spp=4, seed=3, progress=False, freeze=f)
            for f in (True, False)]
    assert [h["loss"] for h in runs[0].history] == pytest.approx([h["loss"] for h in runs[1].history], rel=1e-5)
    assert np.abs(runs[0].final["alpha"] - runs[1].final["alpha"]).max() < 1e-5


def test_a_run_leaves_no_gradient_state_behind(problem):
    """A run without the uncertainty pass, then a run with it on new scenes: the second one's
    forward-mode pass (inside mi.render's isolated AD scope) must not reach the first run's
    gradient-enabled leaves (it failed with 'ad_traverse(): ... outside of the current
    dr.isolate_grad() scope' when the scenes kept them)."""
    truth, obs = problem
    first = inv.invert_maps(obs, {"alpha": 0.3}, iterations=3, spp=4, seed=1, progress=False, uncertainty=False)
    assert np.array_equal(np.asarray(mi.traverse(obs[0].scene)["plane.bsdf.alpha.data"])[..., 0],
                          first.final["alpha"].astype(np.float32))            # the scenes keep the result
    again = []
    for light in range(2):
        scene = mi.load_dict(inv.observations.plane_scene_dict(truth, bsdf=BSDF, light=light, res=RES, views=(0.0, 180.0)))
        again.append(inv.Observation(scene, inv.observations.render_stokes_np(scene, 0, 64, seed=0)))
    second = inv.invert_maps(again, {"alpha": 0.3}, iterations=2, spp=4, seed=1, progress=False)
    assert np.isfinite(second.rel_stderr["alpha"]).any()


#: a frozen step whose recording meets Dr.Jit arrays from NumPy memory waiting in cyclic garbage: the Python
#: objects the step makes trigger the collector during the recording (argv[1]: "guarded" or "plain" dr.freeze)
_GARBAGE_DURING_RECORDING = """
import gc, sys
import numpy as np
import drjit as dr
import mitsuba as mi
from hyde_bsdf.inverse._common import freeze_step
mi.set_variant("llvm_ad_rgb")

class Holder:
    pass

def step(x):
    junk = [[i] for i in range(20000)]          # allocations: the collector's threshold is reached here
    return dr.sum(x * 2.0 + 1.0)

fn = freeze_step(step) if sys.argv[1] == "guarded" else dr.freeze(step)
x = mi.Float(np.arange(100, dtype=np.float32))
for it in range(3):
    for _ in range(50):
        h = Holder()
        h.arr = mi.TensorXf(np.random.rand(1000).astype(np.float32))   # Dr.Jit array from NumPy memory
        h.cycle = h                                                    # freed only by the collector
        del h
    assert float(fn(x)[0]) == 10000.0
print("recorded and replayed")
"""


def test_frozen_step_pauses_the_collector_while_dr_jit_records():
    """The frozen optimisation step (invert_maps, invert) runs with the garbage collector paused: Dr.Jit arrays
    made from NumPy memory that wait in cyclic garbage would otherwise be freed through host callbacks during the
    recording, which Dr.Jit cannot record -- it aborts the process (shown with the plain dr.freeze).  Two child
    processes, ~5 s."""
    import subprocess
    import sys

    from pathlib import Path

    run = lambda how: subprocess.run([sys.executable, "-c", _GARBAGE_DURING_RECORDING, how],  # noqa: E731
                                     capture_output=True, text=True, timeout=300, cwd=Path(__file__).parents[1])
    guarded, plain = run("guarded"), run("plain")
    assert guarded.returncode == 0 and "recorded and replayed" in guarded.stdout, guarded.stderr[-2000:]
    assert plain.returncode != 0 and "cannot be recorded" in plain.stderr, (plain.returncode, plain.stderr[-2000:])
