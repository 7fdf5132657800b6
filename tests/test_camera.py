"""The scene from calibration (hyde_bsdf.render.camera): the CV pinhole convention (world-to-camera R, t;
x right, y down, z forward; pixel centres at integers) converted to Mitsuba's perspective sensor.

Physics checked: small glowing spheres at known 3-D points, rendered through the sensor built from a
calibration with a tilted, rolled pose and an off-centre principal point (64 x 48 pixels), appear
with their intensity centroid on the pixel the pinhole model predicts within 0.5 px -- so the image's
x/y flips, the field of view and the principal-point offset are right.  A directional light's
``towards_light`` points at the light.  Bad calibrations are one-line UsageErrors.
"""
import json

import numpy as np
import pytest

from hyde_bsdf.errors import UsageError
from hyde_bsdf.render.camera import Calibration, load_cameras, load_lights

mi = pytest.importorskip("mitsuba")


def _pose(eye, target, roll_deg):
    """World-to-camera R, t of a CV camera at ``eye`` looking at ``target`` (world z up), rolled."""
    z = np.asarray(target, float) - eye
    z /= np.linalg.norm(z)
    x = np.cross(z, [0.0, 0.0, 1.0])
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    R = np.stack([x, y, z])                      # rows: camera axes in world coordinates
    c, s = np.cos(np.radians(roll_deg)), np.sin(np.radians(roll_deg))
    R = np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]]) @ R
    return R, -R @ np.asarray(eye, float)


CAMERA = {"width": 64, "height": 48, "fx": 58.0, "fy": 58.0, "cx": 27.3, "cy": 26.1, "distortion": [0, 0, 0, 0]}


@pytest.fixture(scope="module")
def calibration():
    R, t = _pose(np.array([3.0, -2.0, 2.5]), [0.2, 0.1, 0.0], roll_deg=17.0)
    return Calibration.from_dict({**CAMERA, "R": R.tolist(), "t": t.tolist()})


def test_marker_lands_on_the_predicted_pixel(calibration):
    prev = mi.variant()
    mi.set_variant("llvm_ad_mono_polarized" if "llvm_ad_mono_polarized" in mi.variants() else mi.variants()[0])
    try:
        points = np.array([[0.2, 0.1, 0.0], [0.5, 0.8, 0.6], [0.8, 0.6, -0.5], [-0.3, -0.8, 0.3], [-0.5, 0.2, 0.8]])
        uv = calibration.project(points)
        assert np.all((uv > 4) & (uv < [60, 44]))                       # all inside the picture
        scene = {"type": "scene", "integrator": {"type": "path", "max_depth": 2},
                 "sensor": calibration.sensor_dict(spp=64)}
        for i, p in enumerate(points):
            scene[f"marker{i}"] = {"type": "sphere", "center": p.tolist(), "radius": 0.04,
                                   "emitter": {"type": "area", "radiance": {"type": "spectrum", "value": 1.0}}}
        img = np.asarray(mi.render(mi.load_dict(scene), spp=64), np.float64)[..., 0]
        for (u, v) in uv:
            r0, c0 = int(round(v)), int(round(u))
            win = img[r0 - 4:r0 + 5, c0 - 4:c0 + 5]
            assert win.sum() > 0, (u, v)
            rows, cols = np.mgrid[r0 - 4:r0 + 5, c0 - 4:c0 + 5]
            cu, cv = (win * cols).sum() / win.sum(), (win * rows).sum() / win.sum()
            assert abs(cu - u) < 0.5 and abs(cv - v) < 0.5, (u, v, cu, cv)
        assert img.sum() == pytest.approx(sum(img[int(round(v)) - 4:int(round(v)) + 5,
                                                  int(round(u)) - 4:int(round(u)) + 5].sum() for u, v in uv), rel=1e-6)
    finally:
        if prev is not None:
            mi.set_variant(prev)


def test_camera_centre_and_json(tmp_path, calibration):
    np.testing.assert_allclose(calibration.center, [3.0, -2.0, 2.5], atol=1e-12)
    path = tmp_path / "cam.json"
    path.write_text(json.dumps({"cameras": [{**CAMERA, "R": calibration.R.tolist(), "t": calibration.t.tolist()}]}))
    (cam,) = load_cameras(path)
    np.testing.assert_allclose(cam.project([[0.2, 0.1, 0.0]]), calibration.project([[0.2, 0.1, 0.0]]))
    lights = tmp_path / "lights.json"
    lights.write_text(json.dumps({"lights": [{"type": "directional", "towards_light": [0, 0, 2], "irradiance": 3},
                                             {"type": "point", "position": [1, 2, 3], "intensity": 30}]}))
    d, p = (light.emitter for light in load_lights(lights))
    assert d["direction"] == [0.0, 0.0, -1.0] and p["position"] == [1.0, 2.0, 3.0]


@pytest.mark.parametrize("change, match", [
    ({"distortion": [0.1, 0, 0, 0]}, r"non-zero distortion \[0.1, 0.0, 0.0, 0.0\]; undistort the images"),
    ({"fy": 60.0}, r"fx = 58 and fy = 60 differ by more than 0.1 %"),
    ({"R": [[1, 0, 0], [0, 1, 0], [0, 0, -1]]}, r"R is not a rotation"),
    ({"t": [0, 0]}, r"t must be a list of 3 numbers"),
    ({"width": 64.5}, r"width and height must be integers"),
])
def test_bad_calibration_is_one_line(change, match, tmp_path):
    d = {**CAMERA, "R": np.eye(3).tolist(), "t": [0, 0, 4], **change}
    path = tmp_path / "cam.json"
    path.write_text(json.dumps(d))
    with pytest.raises(UsageError, match=match) as info:
        load_cameras(path)
    assert "\n" not in str(info.value) and str(path) in str(info.value)
    with pytest.raises(UsageError, match="no such file"):
        load_cameras(tmp_path / "missing.json")


def test_superpixel_binning_keeps_the_projection(calibration):
    """A DoFP camera calibrated on its raw pixels: the super-pixel image's calibration ("binning": 2)
    puts a point at (u_raw - 0.5) / 2 -- the super-pixel covering raw pixels 2i, 2i + 1 is centred at
    raw coordinate 2i + 0.5."""
    raw = Calibration(128, 96, 116.0, 116.0, 55.1, 52.7, calibration.R, calibration.t)
    sp = raw.binned(2)
    p = [[0.5, 0.8, 0.6], [0.2, 0.1, 0.0]]
    np.testing.assert_allclose(sp.project(p), (raw.project(p) - 0.5) / 2, atol=1e-12)
    d = {"width": 128, "height": 96, "fx": 116.0, "fy": 116.0, "cx": 55.1, "cy": 52.7, "binning": 2,
         "R": calibration.R.tolist(), "t": calibration.t.tolist()}
    assert Calibration.from_dict(d).width == 64
    with pytest.raises(UsageError, match="binning must be 1 or 2"):
        Calibration.from_dict({**d, "binning": 3})


def test_polarized_calibrated_light():
    """A point light behind a polarizer sheet ("polarizer": 45) lighting a glass-like plane seen by a
    calibrated camera near the mirror direction: S0 is half that of the bare light (a polarizer passes
    half of unpolarized light), and S2, zero for unpolarized light after one reflection, is not (the
    C element); adding the quarter-wave retarder ("retarder": 45 after "polarizer": 0) makes S3 non-zero."""
    from hyde_bsdf.render.camera import calibrated_scene, light_spec

    prev = mi.variant()
    mi.set_variant("llvm_ad_mono_polarized")
    try:
        from hyde_bsdf import register

        register()
        R, t = _pose(np.array([2.0, 0.0, 2.0]), [0.0, 0.0, 0.0], 0.0)
        cam = Calibration.from_dict({"width": 16, "height": 16, "fx": 20.0, "fy": 20.0, "cx": 7.5, "cy": 7.5,
                                     "R": R.tolist(), "t": t.tolist()})
        base = {"integrator": {"type": "stokes", "integrator": {"type": "path", "max_depth": 2}},
                "plane": {"type": "rectangle", "bsdf": {"type": "hyde", "alpha": 0.3, "eta": 1.5}}}
        out = {}
        for key, extra in (("bare", {}), ("pol45", {"polarizer": 45.0}), ("circ", {"polarizer": 0.0, "retarder": 45.0})):
            light = light_spec({"type": "point", "position": [-2.0, 0.0, 2.0], "intensity": 10, **extra})
            img = mi.render(calibrated_scene(base, [cam], light, spp=16), spp=64, seed=3)
            arr = np.asarray(img, np.float64)
            S = arr[..., 1::3].reshape(-1, 4)          # channels Y, S0.R, S0.G, S0.B, S1.R, ...: S0..S3 (mono)
            out[key] = S[S[:, 0] > 0].mean(axis=0)
        assert out["pol45"][0] / out["bare"][0] == pytest.approx(0.5, rel=0.03)
        assert abs(out["bare"][2]) < 1e-3 * out["bare"][0] and abs(out["pol45"][2]) > 0.2 * out["pol45"][0]
        assert abs(out["bare"][3]) < 1e-3 * out["bare"][0] and abs(out["circ"][3]) > 0.2 * out["circ"][0]
    finally:
        if prev is not None:
            mi.set_variant(prev)
    with pytest.raises(UsageError, match="a retarder needs a polarizer"):
        light_spec({"type": "point", "position": [0, 0, 1], "retarder": 45})
