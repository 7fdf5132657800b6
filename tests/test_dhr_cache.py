"""The DHR table's disk cache is verified at every load (issue 10, "a trustworthy cache").

Behaviour checked: a cache file that was tampered with or damaged in any way -- rho scaled
(with or without a matching checksum), a wrong shape, NaN, a different grid or build
parameters, an old-format file, bytes that are not an .npz, a directory in its place -- is
refused with a DHRCacheWarning naming the file, rebuilt, and written back atomically (no
temporary file left); a good file is used without rebuilding; an empty HYDE_BSDF_CACHE means
the default folder.  Physics: a table whose rho was halved would raise the diffuse F_00 of
glass at 30 deg from 0.0010 to 0.0067 /sr; after the reload F_00 is the untampered value.
"""
import json
import math
import warnings
from pathlib import Path

import numpy as np
import pytest

import hyde_bsdf
from hyde_bsdf.model import dhr


@pytest.fixture(scope="module")
def good_table():
    """The real table (from the session cache or built once), and its arrays."""
    return dhr.load_table("vgroove")


@pytest.fixture
def cache(tmp_path, monkeypatch, good_table):
    """A private cache folder, an empty in-memory cache, and build_table replaced by a counter
    that hands back the real table (so each case costs a load, not a 1-3 s rebuild)."""
    folder = tmp_path / "cache"
    monkeypatch.setenv("HYDE_BSDF_CACHE", str(folder))
    monkeypatch.setattr(dhr, "_TABLES", {})
    builds = []

    def fake_build(shadowing="vgroove", progress=True):
        builds.append(shadowing)
        return good_table

    monkeypatch.setattr(dhr, "build_table", fake_build)
    folder.mkdir()
    return folder, builds


def write_npz(path, arrays):
    with open(path, "wb") as fh:          # np.savez(path) would append ".npz" to odd names
        np.savez(fh, **arrays)


def stored_arrays(table):
    """What _save_table writes, as a dict to tamper with."""
    meta = json.dumps(dhr._build_params("vgroove"), sort_keys=True)
    arrays = {n: np.array(getattr(table, n)) for n in dhr._ARRAYS}
    return dict(meta=np.array(meta), checksum=np.array(dhr._checksum(meta, arrays)),
                build_seconds=np.array(1.0), **arrays)


def reseal(arrays):
    """Recompute the checksum after tampering: only the deeper checks can catch it then."""
    arrays["checksum"] = np.array(dhr._checksum(str(arrays["meta"][()]), arrays))
    return arrays


def assert_refused_and_rebuilt(folder, builds, reason):
    path = dhr.cache_path("vgroove")
    with pytest.warns(dhr.DHRCacheWarning, match=reason) as rec:
        table = dhr.load_table("vgroove")
    assert path.name in str(rec[0].message)            # the message names the file
    assert builds == ["vgroove"]
    # written back: a fresh process would load it without rebuilding or warning
    dhr._TABLES.clear()
    with warnings.catch_warnings():
        warnings.simplefilter("error", dhr.DHRCacheWarning)
        again = dhr.load_table("vgroove")
    assert builds == ["vgroove"]
    np.testing.assert_array_equal(again.rho, table.rho)
    assert sorted(p.name for p in folder.iterdir()) == [path.name]    # no temporary files
    return table


def test_a_good_cache_file_is_used_without_rebuilding(cache, good_table):
    folder, builds = cache
    dhr._save_table(dhr.cache_path("vgroove"), good_table)
    with warnings.catch_warnings():
        warnings.simplefilter("error", dhr.DHRCacheWarning)
        table = dhr.load_table("vgroove")
    assert builds == []
    np.testing.assert_array_equal(table.rho, good_table.rho)


def tamper_scale_resealed(a):
    a["rho"] = a["rho"] * 0.5
    a["rho_avg"] = dhr._rho_average(a["x"], a["rho"])
    return reseal(a)


def tamper_scale(a):
    a["rho"] = a["rho"] * 0.5
    return a


def tamper_shape(a):
    a["rho"] = a["rho"][:-1]
    return reseal(a)


def tamper_nan(a):
    a["rho"] = a["rho"].copy()
    a["rho"][7, 3] = np.nan
    return reseal(a)


def tamper_grid(a):
    a["x"] = np.linspace(0.0, 1.0, a["x"].size)
    return reseal(a)


def tamper_params(a):
    meta = json.loads(str(a["meta"][()]))
    meta["table_version"] -= 1
    a["meta"] = np.array(json.dumps(meta, sort_keys=True))
    return reseal(a)


def tamper_old_format(a):
    del a["meta"], a["checksum"]
    return a


def tamper_avg(a):
    a["rho_avg"] = a["rho_avg"] + 1e-3
    return reseal(a)


@pytest.mark.parametrize("tamper, reason", [
    (tamper_scale_resealed, "re-integrated"),
    (tamper_scale, "checksum"),
    (tamper_shape, "shape"),
    (tamper_nan, "non-finite"),
    (tamper_grid, "grid"),
    (tamper_params, "other parameters"),
    (tamper_old_format, "lacks"),
    (tamper_avg, "rho_avg"),
], ids=lambda v: getattr(v, "__name__", v))
def test_tampered_cache_file_is_refused_named_and_rebuilt(cache, good_table, tamper, reason):
    folder, builds = cache
    write_npz(dhr.cache_path("vgroove"), tamper(stored_arrays(good_table)))
    assert_refused_and_rebuilt(folder, builds, reason)


@pytest.mark.parametrize("content", [b"", b"not a table at all", b"PK\x03\x04truncated"],
                         ids=["empty", "text", "truncated-zip"])
def test_unreadable_cache_file_is_refused_and_rebuilt(cache, content):
    folder, builds = cache
    dhr.cache_path("vgroove").write_bytes(content)
    assert_refused_and_rebuilt(folder, builds, "cannot be read")


def test_directory_in_place_of_the_cache_file_leaves_no_temporary_files(cache, capsys):
    folder, builds = cache
    path = dhr.cache_path("vgroove")
    path.mkdir()
    for _ in range(2):                       # two runs: each warns, rebuilds, leaks nothing
        dhr._TABLES.clear()
        with pytest.warns(dhr.DHRCacheWarning) as record:
            dhr.load_table("vgroove")
        texts = [str(w.message) for w in record]
        assert any(path.name in text for text in texts), texts
        assert any("could not cache the DHR table" in text for text in texts), texts
    assert builds == ["vgroove", "vgroove"]
    assert [p.name for p in folder.iterdir()] == [path.name] and not any(path.iterdir())


def test_empty_cache_variable_means_the_default_folder(monkeypatch, tmp_path):
    monkeypatch.setenv("HOME", str(tmp_path / "home"))
    monkeypatch.setenv("HYDE_BSDF_CACHE", "")
    assert dhr.cache_dir() == Path(tmp_path / "home" / ".cache" / "hyde-bsdf")
    monkeypatch.setenv("HYDE_BSDF_CACHE", "   ")
    assert dhr.cache_dir() == Path(tmp_path / "home" / ".cache" / "hyde-bsdf")
    monkeypatch.delenv("HYDE_BSDF_CACHE")
    assert dhr.cache_dir() == Path(tmp_path / "home" / ".cache" / "hyde-bsdf")
    monkeypatch.setenv("HYDE_BSDF_CACHE", str(tmp_path / "elsewhere"))
    assert dhr.cache_dir() == tmp_path / "elsewhere"


def test_halved_rho_with_valid_checksum_does_not_reach_the_model(tmp_path, monkeypatch, good_table):
    """End to end, with the real rebuild: the diffuse F_00 of glass (n = 1.5) at theta_i =
    theta_r = 30 deg, rms_slope 0.3, is 0.0010 /sr; the resealed cache with rho * 0.5 of the
    issue would make it 0.0067 /sr (and renders 1.5x brighter).  After the reload it is 0.0010."""
    geometry = (math.radians(30), math.radians(30), 0.0)
    kw = dict(rms_slope=0.3, n=1.5, k=0.0)
    ref = hyde_bsdf.pbrdf(*geometry, **kw)[0, 0] - hyde_bsdf.pbrdf(*geometry, **kw, diffuse=False)[0, 0]
    assert ref == pytest.approx(0.0010, abs=5e-5)
    rho = float(good_table(geometry[0], 0.3))
    assert ref * (1 - 0.5 * rho) / (1 - rho) == pytest.approx(0.0067, abs=3e-4)   # what it would be
    monkeypatch.setenv("HYDE_BSDF_CACHE", str(tmp_path))
    monkeypatch.setattr(dhr, "_TABLES", {})
    write_npz(dhr.cache_path("vgroove"), tamper_scale_resealed(stored_arrays(good_table)))
    with pytest.warns(dhr.DHRCacheWarning, match="re-integrated"):
        F = hyde_bsdf.pbrdf(*geometry, **kw)
    diffuse = F[0, 0] - hyde_bsdf.pbrdf(*geometry, **kw, diffuse=False)[0, 0]
    assert diffuse == pytest.approx(ref, rel=1e-9)
    np.testing.assert_allclose(dhr.load_table("vgroove").rho, good_table.rho, rtol=0, atol=1e-12)
    assert [p.name for p in tmp_path.iterdir()] == [dhr.cache_path("vgroove").name]
