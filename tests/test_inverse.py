"""Differentiable inverse rendering with the hyde plugin (hyde_bsdf.inverse), on tiny images.

Physics checked: the AD gradient of a rendered Stokes loss (llvm_ad_spectral_polarized,
``stokes`` around ``path``) equals the central finite difference of the same loss and
seed (including the rms_slope path through the DHR texture, diffuse on); a few Adam
steps from a wrong material lower the loss and move every parameter towards the truth.
"""
import math

import numpy as np
import pytest

import mitsuba as mi

from hyde_bsdf import inverse as inv

RES, SPP = 16, 16
AT = {"rms_slope": 0.4, "eta": 2.0, "k": 4.0}


@pytest.fixture(scope="module")
def tiny():
    previous = mi.variant()
    inv.prepare()
    scene = inv.scalar.load_scene(None, res=RES, spp=SPP)
    ref = inv.scalar.render_reference(scene, inv.scalar.TRUTH, 64, seed=0)
    yield scene, ref
    if previous is not None and previous != mi.variant():
        mi.set_variant(previous)


def test_loss_is_zero_at_reference_and_mask_excludes_silhouette(tiny):
    scene, ref = tiny
    fn = inv.StokesLoss(ref)
    assert fn.numpy(ref) == 0.0
    assert fn.mask_np.sum() > 0.3 * RES * RES         # the sphere fills most of the frame
    assert not fn.mask_np[0].any() and not fn.mask_np[:, 0].any()
    # unpolarized lights, one bounce: S3 = 0 exactly (Eq. 11 maps (1,0,0,0) to (M00, M01, 0, 0))
    assert np.abs(ref[3]).max() == 0.0
    assert np.abs(ref[1]).max() > 0.05 * ref[0].max()  # but S1, S2 carry the linear polarization
    with pytest.raises(ValueError, match="components"):
        inv.StokesLoss(ref, components="s1")


def test_ad_gradient_equals_finite_difference_same_seed(tiny):
    """Same samples for the AD pass and both FD renders: agreement to the FD truncation error."""
    scene, ref = tiny
    fn = inv.StokesLoss(ref)
    _, ad = inv.scalar.loss_and_gradient(scene, fn, AT, spp=SPP, seed=3, seed_grad=3)
    for p in inv.PARAMETERS:
        fd = inv.scalar.finite_difference_gradient(scene, fn, AT, p, rel_step=1e-2, spp=SPP, seed=3)
        assert ad[p] == pytest.approx(fd, rel=5e-3), p
    # at AT every parameter is too large, so the loss grows with rms_slope and falls with eta
    assert ad["rms_slope"] > 0 and ad["eta"] < 0


def test_decorrelated_gradient_pass_has_right_sign_and_size(tiny):
    """mi.render's own (decorrelated) gradient pass, as the optimizer uses it: over 4 seeds its
    mean has the sign of the FD mean and lies within 40 % of it (16x16 pixels, 16 spp: noisy)."""
    scene, ref = tiny
    fn = inv.StokesLoss(ref)
    ad = {p: [] for p in inv.PARAMETERS}
    fd = {p: [] for p in inv.PARAMETERS}
    for seed in (5, 6, 7, 8):
        _, g = inv.scalar.loss_and_gradient(scene, fn, AT, spp=SPP, seed=seed)
        for p in inv.PARAMETERS:
            ad[p].append(g[p])
            fd[p].append(inv.scalar.finite_difference_gradient(scene, fn, AT, p, rel_step=1e-2, spp=SPP, seed=seed))
    for p in inv.PARAMETERS:
        a, f = np.mean(ad[p]), np.mean(fd[p])
        assert math.copysign(1, a) == math.copysign(1, f), p
        assert a == pytest.approx(f, rel=0.4), p


def test_few_adam_steps_reduce_loss_and_approach_truth(tiny):
    scene, ref = tiny
    start = {"rms_slope": 0.4, "eta": 1.0, "k": 2.0}
    res = inv.invert(scene, inv.StokesLoss(ref), start, iterations=12, lr=0.05, spp=SPP, seed=10,
                     truth=inv.scalar.TRUTH, progress=False, average_last=1)
    first, last = res.history[0], res.history[-1]
    assert last["loss"] < 0.3 * first["loss"]
    for p in inv.PARAMETERS:
        assert abs(math.log(last[p] / inv.scalar.TRUTH[p])) < abs(math.log(start[p] / inv.scalar.TRUTH[p])), p
    assert len(res.history) == 12 and res.seconds_per_iteration > 0


def test_parameter_keys_and_errors(tiny):
    scene, _ = tiny
    keys = inv.scalar.parameter_keys(mi.traverse(scene))
    assert keys == {"rms_slope": "sphere.bsdf.rms_slope.value", "eta": "sphere.bsdf.eta.value",
                    "k": "sphere.bsdf.k.value"}
    empty = mi.load_dict({"type": "scene", "s": {"type": "sphere", "bsdf": {"type": "diffuse"}}})
    with pytest.raises(ValueError, match="exactly one BSDF parameter for 'rms_slope'"):
        inv.scalar.parameter_keys(mi.traverse(empty))
    with pytest.raises(ValueError, match="start must give a value"):
        inv.invert(scene, inv.StokesLoss(tiny[1]), {"eta": 1.0}, iterations=1)


def test_cli_invert_end_to_end(tmp_path, capsys):
    from hyde_bsdf.app.cli import main

    rc = main(["invert", "--res", "16", "--spp", "16", "--spp-ref", "64", "--iterations", "3", "--fit", "rms_slope",
                       "-o", str(tmp_path)])
    out = capsys.readouterr().out
    assert rc == 0
    assert "rms_slope start 0.6" in out and "(fixed)" in out
    lines = (tmp_path / "invert_history.csv").read_text().splitlines()
    assert lines[1].startswith("iteration,loss") and len(lines) == 2 + 3
    assert (tmp_path / "invert.png").stat().st_size > 5_000
    assert out.count("WARNING: rms_slope") == 1      # 3 iterates: too few to call it converged, said once
    assert main(["invert", "--start", "rms_slope=abc"]) == 2
    assert "not a number" in capsys.readouterr().err


def test_stopped_early_scalar_inversion_warns(tiny):
    """12 iterations from a start far from the truth: eta and k are still moving over the averaged
    window, so the averaged values are not results -- a NotConvergedWarning (once per parameter) and
    result.converged False for them."""
    scene, ref = tiny
    start = {"rms_slope": 0.4, "eta": 1.0, "k": 2.0}
    with pytest.warns(inv.NotConvergedWarning) as caught:
        res = inv.invert(scene, inv.StokesLoss(ref), start, iterations=12, lr=0.05, spp=SPP, seed=10,
                         progress=False, average_last=8)
    messages = [str(w.message) for w in caught if issubclass(w.category, inv.NotConvergedWarning)]
    assert len(messages) == len(set(messages)) == len(res.warnings)
    assert not all(res.converged.values())
    assert all(m.split()[0] in inv.PARAMETERS and "has not converged" in m for m in messages)
