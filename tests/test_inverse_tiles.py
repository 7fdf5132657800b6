"""Per-texel maps in tiles of texels, each an independent task (hyde_bsdf.inverse.tiles).

Physics checked: with nearest-neighbour texels a pixel wholly inside one tile's texels depends on
those texels only, so fitting each tile from the film crop that holds its pixels recovers the same
map as one fit of the whole picture -- within the standard errors, since a crop renders other random
numbers than the whole film (same seeds, other pixel indices).  A tile's result does not depend on
the executor that runs it: the same tasks in this process and on a dask LocalCluster give the same
maps to float noise (Dr.Jit's LLVM backend sums the texture gradients with parallel atomics, whose
order varies from run to run: measured 2e-8 relative between two serial runs, 6e-9 dask against
serial; the tolerance is 1e-6).  A dask
Client given instead of its executor is refused with one line; the memory check names --tiles.
"""
import json
import warnings

import numpy as np
import pytest

from hyde_bsdf.errors import UsageError

pytestmark = pytest.mark.usefixtures("map_variant")

MAP = 6                      # texels per side
TRUTH = 0.2 + 0.3 * np.linspace(0, 1, MAP * MAP).reshape(MAP, MAP)
OPTIONS = dict(iterations=16, spp=4, lr=0.08, seed=3, uncertainty_spp=8)


def _sample_xml(alpha_file):
    return f"""<scene version="3.0.0">
  <integrator type="stokes"><integrator type="path"><integer name="max_depth" value="2"/></integrator></integrator>
  <shape type="rectangle" id="plane">
    <bsdf type="hyde" id="sample">
      <texture type="bitmap" name="alpha">
        <string name="filename" value="{alpha_file}"/>
        <boolean name="raw" value="true"/>
        <string name="filter_type" value="nearest"/>
      </texture>
      <float name="eta" value="1.5"/>
    </bsdf>
  </shape>
</scene>"""


@pytest.fixture(scope="module")
def capture(tmp_path_factory):
    """A 6 x 6 alpha map on a 2 x 2 plane, one 72 x 64-pixel camera at 45 deg, two point lights; the
    references rendered at 64 spp from the truth (no added noise: the render noise is the noise)."""
    import mitsuba as mi

    from hyde_bsdf.inverse.observations import render_stokes_np
    from hyde_bsdf.inverse.tiles import Capture
    from hyde_bsdf.render.camera import calibrated_scene, load_cameras, load_lights

    d = tmp_path_factory.mktemp("tiles")
    eye = np.array([2.2, 0.0, 2.2])
    z = -eye / np.linalg.norm(eye)
    x = np.cross(z, [0.0, 0.0, 1.0])
    x /= np.linalg.norm(x)
    R = np.stack([x, np.cross(z, x), z])
    (d / "camera.json").write_text(json.dumps({"width": 72, "height": 64, "fx": 80.0, "fy": 80.0, "cx": 35.5,
                                               "cy": 31.5, "R": R.tolist(), "t": (-R @ eye).tolist()}))
    (d / "lights.json").write_text(json.dumps({"lights": [
        {"type": "point", "position": [-2.5, 0.4, 2.5], "intensity": 20},
        {"type": "point", "position": [0.4, 2.5, 2.5], "intensity": 20}]}))
    mi.Bitmap(TRUTH.astype(np.float32)[..., None]).write(str(d / "truth.exr"))
    mi.Bitmap(np.full((MAP, MAP, 1), 0.3, np.float32)).write(str(d / "start.exr"))
    (d / "truth.xml").write_text(_sample_xml(d / "truth.exr"))
    (d / "sample.xml").write_text(_sample_xml(d / "start.exr"))
    cams, lights = load_cameras(d / "camera.json"), load_lights(d / "lights.json")
    refs = []
    for j, light in enumerate(lights):
        S = render_stokes_np(calibrated_scene(str(d / "truth.xml"), cams, light, spp=64), 0, 64, seed=10 + j)
        refs.append(({"reference": S, "measured": ("S0", "S1", "S2", "S3"), "sigma": None, "mask": None},))
    return Capture(str(d / "sample.xml"), tuple(cams), tuple(lights), tuple(refs), spp=4)


@pytest.fixture(scope="module")
def serial(capture):
    from hyde_bsdf.inverse.tiles import invert_maps_tiled

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return invert_maps_tiled(capture, {"alpha": 0.3}, tiles=(2, 2), progress=False, **OPTIONS)


def test_tiles_cover_the_map_and_crop_the_film(capture):
    """Four tiles of 3 x 3 texels; each task's crops hold only its own pixels, smaller than the film."""
    from hyde_bsdf.inverse.tiles import plan_tiles, tile_bounds

    assert tile_bounds((MAP, MAP), 2) == [(0, 3, 0, 3), (0, 3, 3, 6), (3, 6, 0, 3), (3, 6, 3, 6)]
    tasks, shape, _ = plan_tiles(capture, {"alpha": 0.3}, tiles=2)
    assert shape == (MAP, MAP) and len(tasks) == 4
    for t in tasks:
        assert len(t.crops) == 2 and t.capture.references == ()
        for _, _, (x0, y0, w, h), ref, _, _, mask in t.crops:
            assert ref.shape == (4, h, w) and mask.shape == (h, w) and mask.any()
            assert w * h < 72 * 64 / 2
    import pickle
    assert pickle.loads(pickle.dumps(tasks[0])).crops[0][2] == tasks[0].crops[0][2]


def test_tiled_maps_agree_with_the_whole_picture_within_the_standard_errors(capture, serial):
    """Tiled (crops, other random numbers) against one fit of the whole pictures: the texels with a
    standard error in both (a noise-free truth render leaves some texels' residuals above the estimated
    noise: not converged, no standard error) agree within 4 combined standard errors, every seen texel
    within 1 %, and both recover the truth (median error < 0.5 %; measured 0.1 %)."""
    from hyde_bsdf.inverse.maps import invert_maps

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        whole = invert_maps(capture.observations(), {"alpha": 0.3}, progress=False, **OPTIONS)
    ok = np.isfinite(serial.stderr["alpha"]) & np.isfinite(whole.stderr["alpha"])
    assert ok.sum() >= 8, ok
    z = (serial.final["alpha"] - whole.final["alpha"]) / np.hypot(serial.stderr["alpha"], whole.stderr["alpha"])
    assert np.abs(z[ok]).max() < 4.0, z[ok]
    seen = serial.seen & whole.seen
    assert np.abs(serial.final["alpha"][seen] / whole.final["alpha"][seen] - 1).max() < 0.01
    for res in (serial, whole):
        assert np.median(np.abs(res.final["alpha"][seen] / TRUTH[seen] - 1)) < 0.005
    assert serial.seen.sum() >= whole.seen.sum() - 8       # only the seam pixels are lost


def test_dask_local_cluster_gives_the_same_maps_as_one_process(capture, serial):
    """The same tasks on a dask LocalCluster (threads, 2 workers): the same maps, standard errors and
    seen mask, to 1e-6 relative (the texture gradients' parallel sums; see the module docstring)."""
    distributed = pytest.importorskip("distributed")
    from hyde_bsdf.inverse.tiles import invert_maps_tiled

    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=False,
                                  dashboard_address=None) as cluster, distributed.Client(cluster) as client:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            res = invert_maps_tiled(capture, {"alpha": 0.3}, tiles=(2, 2), executor=client.get_executor(),
                                    progress=False, **OPTIONS)
        with pytest.raises(UsageError, match=r"^executor is a dask Client; pass client.get_executor\(\)"):
            invert_maps_tiled(capture, {"alpha": 0.3}, executor=client, progress=False, **OPTIONS)
    np.testing.assert_array_equal(res.seen, serial.seen)
    np.testing.assert_allclose(res.final["alpha"], serial.final["alpha"], rtol=1e-6)
    np.testing.assert_allclose(res.stderr["alpha"], serial.stderr["alpha"], rtol=1e-6, equal_nan=True)


def test_memory_estimate_of_a_tile():
    """1224 x 1024 px at 4 spp in one piece needs ~16 GB (400 MiB + 3 kB per sample); two tiles of a
    sixteenth at once fit in 4 GiB (the refusal naming --tiles is test_command_line_memory_refusal_names_tiles)."""
    from hyde_bsdf.resources import inversion_bytes

    assert 15e9 < inversion_bytes(1224 * 1024, 4) < 16.5e9
    assert 2 * inversion_bytes(1224 * 1024 // 16, 4) < 4 * 2**30


def _cli_files(capture):
    """The capture as the command line takes it: sample XML, camera and light JSON, mono Stokes EXRs."""
    from pathlib import Path

    from hyde_bsdf.io.stokes_exr import write_camera_stokes

    d = Path(capture.scene).parent
    refs = []
    for j, row in enumerate(capture.references):
        S = row[0]["reference"]
        refs += ["--reference", str(write_camera_stokes(d / f"ref{j}.exr", {f"S{c}": S[c] for c in range(4)}))]
    return ["--maps", "--scene", capture.scene, "--camera", str(d / "camera.json"), "--light",
            str(d / "lights.json")] + refs


def test_command_line_tiles_end_to_end(capsys, capture, tmp_path):
    """``invert --maps ... --tiles 2 --workers 2`` (a process pool) writes the stitched 6 x 6 map, its
    standard errors and seen mask, and reports the tiles; the map is near the truth (median error < 2 %
    after 12 iterations)."""
    from hyde_bsdf.app.cli import main

    assert main(["invert"] + _cli_files(capture) + ["--tiles", "2", "--workers", "2", "--iterations", "12",
                                                    "--fit", "alpha", "-o", str(tmp_path)]) == 0
    out = capsys.readouterr().out
    assert "tiles: 4 task(s) of 2x2" in out
    alpha, seen = np.load(tmp_path / "alpha.npy"), np.load(tmp_path / "alpha_seen.npy").astype(bool)
    assert alpha.shape == (MAP, MAP) and seen.sum() >= 30 and np.isfinite(alpha[seen]).all()
    assert np.median(np.abs(alpha[seen] / TRUTH[seen] - 1)) < 0.02
    assert np.load(tmp_path / "alpha_stderr.npy").shape == (MAP, MAP)


@pytest.mark.parametrize("extra, words", [
    (["--workers", "2"], "--workers and --scheduler run tiles: give --tiles"),
    (["--tiles", "0"], "--tiles must be N or RxC with integers >= 1"),
    (["--tiles", "2x3x4"], "--tiles must be N or RxC"),
    (["--tiles", "2", "--workers", "0"], "--workers must be an integer >= 1, got 0"),
    (["--tiles", "2", "--workers", "2", "--scheduler", "tcp://127.0.0.1:1"], "not both"),
    (["--tiles", "9"], "tiles must be 1..6 x 1..6 for a 6 x 6-texel map, got 9 x 9"),
])
def test_command_line_tiles_mistakes_are_one_line(capsys, capture, tmp_path, extra, words):
    from hyde_bsdf.app.cli import main

    assert main(["invert"] + _cli_files(capture) + extra + ["-o", str(tmp_path)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and words in err[0], err


def test_command_line_memory_refusal_names_tiles(capsys, capture, monkeypatch, tmp_path):
    """Too little memory for the whole picture: the refusal names --tiles; with tiles, names --workers too."""
    from hyde_bsdf.app.cli import main

    monkeypatch.setattr("hyde_bsdf.resources.available_memory", lambda: 64 * 2**20)
    assert main(["invert"] + _cli_files(capture) + ["-o", str(tmp_path)]) == 2
    assert "--tiles N" in capsys.readouterr().err
    assert main(["invert"] + _cli_files(capture) + ["--tiles", "2", "-o", str(tmp_path)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "use more --tiles (smaller crops), a lower --spp or fewer --workers" in err[0], err


@pytest.mark.parametrize("filter_type", ["nearest", "bilinear"])
def test_filter_probe_of_a_large_map_stays_in_range(filter_type):
    """The bilinear/nearest probe writes a pattern within the parameter's range at any size: a 256 x 256
    alpha map (65 536 texels, the 5-megapixel capture's) is told apart without the plugin refusing a
    texel value (the old pattern grew with the texel index, to alpha ~200 there)."""
    import mitsuba as mi

    from hyde_bsdf.inverse.maps import filters_bilinearly
    from hyde_bsdf.inverse.observations import MAP_PARAMETERS, map_keys

    tex = {"type": "bitmap", "bitmap": mi.Bitmap(np.full((256, 256, 1), 0.3, np.float32)), "raw": True,
           "filter_type": filter_type}
    scene = mi.load_dict({"type": "scene", "plane": {"type": "rectangle", "bsdf": {"type": "hyde", "alpha": tex}}})
    params = mi.traverse(scene)
    key = map_keys(params)["alpha"]
    assert filters_bilinearly(params, key, (256, 256, 1), MAP_PARAMETERS["alpha"][1]) == (filter_type == "bilinear")


def test_command_line_scheduler_runs_the_tiles_on_a_dask_cluster(capsys, capture, tmp_path):
    """``--scheduler ADDRESS``: the tiles go to the dask cluster there (a LocalCluster in this process,
    threads, 2 workers) and the stitched map is written as with the tiles run here."""
    distributed = pytest.importorskip("distributed")
    from hyde_bsdf.app.cli import main

    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=False,
                                  dashboard_address=None) as cluster:
        assert main(["invert"] + _cli_files(capture) + ["--tiles", "2", "--scheduler", cluster.scheduler_address,
                                                        "--iterations", "6", "--no-uncertainty", "--fit", "alpha",
                                                        "-o", str(tmp_path)]) == 0
    assert "tiles: 4 task(s) of 2x2" in capsys.readouterr().out
    alpha, seen = np.load(tmp_path / "alpha.npy"), np.load(tmp_path / "alpha_seen.npy").astype(bool)
    assert seen.sum() >= 30 and np.isfinite(alpha[seen]).all()
