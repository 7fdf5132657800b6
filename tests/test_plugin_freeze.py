"""``dr.freeze``: an optimisation loop (render, loss, backward) frozen with ``hyde`` gives the
same losses and parameter trajectory as the unfrozen loop, as it does with roughconductor, and
replays instead of re-recording.  With ``shadowing="smith", diffuse="none"`` hyde's frozen loop
equals roughconductor's (the same BSDF).  What makes freezing possible: every Dr.Jit value the
plugin reads is reachable by Dr.Jit's traversal (textures are Mitsuba objects; the DHR lookup
declares its textures with ``DRJIT_STRUCT``)."""
import numpy as np
import pytest


def _scene(mi, bsdf):
    return mi.load_dict({
        "type": "scene", "integrator": {"type": "direct"},
        "sensor": {"type": "perspective", "fov": 30,
                   "to_world": mi.ScalarTransform4f().look_at([0, 0, 4], [0, 0, 0], [0, 1, 0]),
                   "film": {"type": "hdrfilm", "width": 16, "height": 16, "pixel_format": "rgb"},
                   "sampler": {"type": "independent", "sample_count": 2}},
        "sphere": {"type": "sphere", "bsdf": bsdf},
        "light": {"type": "point", "position": [2.0, 2.0, 3.0], "intensity": 30.0},
        "sky": {"type": "constant", "radiance": 0.2}})


def _loop(mi, bsdf, key, start, frozen, iterations=4):
    """Adam on `key` towards the image at the texture's own start values; returns (losses, values)."""
    import drjit as dr

    scene = _scene(mi, bsdf())
    params = mi.traverse(scene)
    ref = mi.render(scene, spp=8, seed=123)
    dr.eval(ref)
    opt = mi.ad.Adam(lr=0.05)
    opt[key] = type(params[key])(start) if not isinstance(start, float) else mi.Float(start)
    params.update(opt)

    def step(scene, ref, seed):
        img = mi.render(scene, params, spp=2, seed=seed)
        loss = dr.mean(dr.square(img - ref), axis=None)
        dr.backward(loss)
        return loss

    fn = dr.freeze(step) if frozen else step
    losses, values = [], []
    for it in range(iterations):
        loss = fn(scene, ref, dr.opaque(mi.UInt32, it))
        opt.step()
        params.update(opt)
        losses.append(float(np.asarray(loss).ravel()[0]))
        values.append(np.asarray(params[key], dtype=float).ravel().copy())
    if frozen:
        assert fn.n_recordings < iterations, "the frozen function never replayed"
    return np.array(losses), np.array(values)


def test_frozen_loop_equals_unfrozen_with_textured_alpha_and_diffuse_term():
    import mitsuba as mi
    import hyde_bsdf
    from hyde_bsdf.mitsuba.variants import set_variant

    set_variant("llvm_ad_rgb", fallback=False)
    hyde_bsdf.register("llvm_ad_rgb")
    data = np.linspace(0.2, 0.6, 16, dtype=np.float32).reshape(4, 4, 1)

    def bsdf():   # vgroove + paper diffuse (the DHR texture); a fresh tensor per scene
        return {"type": "hyde", "alpha": {"type": "bitmap", "raw": True, "data": mi.TensorXf(data)},
                "eta": 0.5, "k": 3.0}
    start = mi.TensorXf(np.full((4, 4, 1), 0.4, np.float32))
    plain = _loop(mi, bsdf, "sphere.bsdf.alpha.data", start, frozen=False)
    frozen = _loop(mi, bsdf, "sphere.bsdf.alpha.data", start, frozen=True)
    assert np.all(plain[0] > 0)
    assert np.allclose(frozen[0], plain[0], rtol=1e-5, atol=0), (frozen[0], plain[0])
    assert np.allclose(frozen[1], plain[1], rtol=1e-5, atol=0)
    assert np.abs(plain[1][-1] - 0.4).max() > 1e-3          # the loop really moved the texels


def test_frozen_hyde_smith_no_diffuse_equals_frozen_roughconductor():
    import mitsuba as mi
    import hyde_bsdf
    from hyde_bsdf.mitsuba.variants import set_variant

    set_variant("llvm_ad_rgb", fallback=False)
    hyde_bsdf.register("llvm_ad_rgb")
    idx = {"alpha": 0.3, "eta": 0.5, "k": 3.0}
    hyde = _loop(mi, lambda: {"type": "hyde", "shadowing": "smith", "diffuse": "none", **idx},
                 "sphere.bsdf.alpha.value", 0.5, frozen=True)
    rc = _loop(mi, lambda: {"type": "roughconductor", "distribution": "beckmann", **idx},
               "sphere.bsdf.alpha.value", 0.5, frozen=True)
    assert np.allclose(hyde[0], rc[0], rtol=2e-4, atol=0), (hyde[0], rc[0])
    assert np.allclose(hyde[1], rc[1], rtol=2e-4, atol=0)
