"""The accuracy atlas (issue 32): the query's rules, the comparison that makes a cell, the CLI's errors, the MoM's
estimate before a long run.

The query's rules are checked on a small synthetic atlas whose numbers are chosen here (so each rule has one
answer: the bound between nodes, the verdict at two standard errors, the range over heights, the index families
and their interpolation); the physics of a cell on a real MoM run of 3 partitions (the 1-D model's diffuse
share is M11's error exactly; the paper's model is within 1.5 dB of exact EM over the lobe of a geometric-optics
surface at 20 deg); the shipped table's coverage and provenance.  About 5 s.
"""
import json
import math

import numpy as np
import pytest

from hyde_bsdf.app.cli import main
from hyde_bsdf.model import accuracy as acc

ELEMENTS = ("M00_dB", "M01", "M11", "M22", "M23")
REGIONS = ("lobe", "specular", "wing")
VARIANTS = ("vgroove/paper", "smith/none")


def _write_atlas(path, err=None):
    """A 4-material, 2-slope, 2-height, 3-angle atlas: error 0.5 (dB or absolute) everywhere, se 0.1, unless
    ``err`` (a function of the index tuple (m, s, h, t, v, e, r)) says otherwise."""
    shape = (4, 2, 2, 3, len(VARIANTS), len(ELEMENTS), len(REGIONS))
    e = np.full(shape, 0.05, np.float32)
    e[..., 0, :] = 0.5
    if err is not None:
        for idx in np.ndindex(*shape):
            val = err(idx)
            if val is not None:
                e[idx] = val
    cell = shape[:4]
    prov = {"statistics": {"specular_half_deg": 2.5}, "package_version": "test", "domain": "1-D",
            "mom": {"cpu_s_total": 1.0}}
    np.savez(path, error=e, signed=e, se=np.full(shape, 0.01, np.float32),
             status=np.zeros(cell, np.int8), coherent=np.full(cell, 0.01, np.float32),
             energy_error=np.zeros(cell, np.float32), lobe_deg=np.broadcast_to([-40.0, 80.0], cell + (2,)),
             wing_deg=np.broadcast_to([-60.0, 88.0], cell + (2,)), cpu_s=np.full(cell[:3], 10.0),
             partitions=np.full(cell[:3], 8.0), partition_wl=np.full(cell[:3], 300.0),
             pts_per_wl=np.full(cell[:3], 10.0), materials=np.array(["PEC", "Al_x", "Au_x", "glass"]),
             material_n=np.array([np.nan, 1.5, 0.2, 1.5]), material_k=np.array([np.nan, 15.0, 3.0, 0.0]),
             rms_slopes=np.array([0.1, 0.3]), heights_wl=np.array([0.5, 2.0]),
             theta_i_deg=np.array([0.0, 40.0, 80.0]), variants=np.array(VARIANTS), elements=np.array(ELEMENTS),
             regions=np.array(REGIONS), status_names=np.array(["ok", "too_costly", "not_converged", "no_signal",
                                                               "not_run"]),
             variant_cost_s=np.array([5e-7, 3e-7]), provenance=np.array(json.dumps(prov)))
    return acc.Atlas(path)


@pytest.fixture
def atlas(tmp_path):
    return _write_atlas(tmp_path / "a.npz")


def test_answer_has_the_issue_schema(atlas):
    """JSON: elements (all 16, each with error and valid), recommended (shadowing, diffuse)."""
    a = acc.accuracy(math.radians(40), 0.1, sigma_h_wl=0.5, atlas=atlas)
    text = json.loads(json.dumps(a))
    assert sorted(text["elements"]) == sorted(name for name, _ in acc.ELEMENTS_16)
    assert all({"error", "valid"} <= set(e) for e in text["elements"].values())
    assert set(text["recommended"]) >= {"shadowing", "diffuse"}
    assert text["elements"]["M00_dB"]["error"] == pytest.approx(0.5) and text["elements"]["M00_dB"]["valid"] is True
    assert text["elements"]["M33"]["error"] == text["elements"]["M22"]["error"]      # in-plane symmetry
    assert text["elements"]["M02"] == {"error": 0.0, "se": 0.0, "valid": True, "status": "valid",
                                      "source": "0 in both on a 1-D surface in the plane of incidence"}


def test_between_nodes_the_bound_is_the_largest_corner(tmp_path):
    """At theta_i = 20 deg (between 0 and 40) the stated M22 error is the larger of the two nodes' (0.3), not
    their mean: a bound."""
    a = _write_atlas(tmp_path / "a.npz", lambda i: 0.3 if (i[3] == 1 and i[5] == 3) else None)
    ans = acc.accuracy(math.radians(20), 0.1, sigma_h_wl=0.5, atlas=a)
    assert ans["elements"]["M22"]["error"] == pytest.approx(0.3)
    assert ans["elements"]["M22"]["valid"] is False                  # 0.3 > tolerance 0.1


def test_verdict_at_two_standard_errors(atlas):
    """valid: error + 2 se <= tolerance; invalid: error > tolerance; undecided between."""
    assert acc._verdict(0.5, 0.2, 1.0) is True
    assert acc._verdict(0.8, 0.2, 1.0) is None
    assert acc._verdict(1.2, 0.01, 1.0) is False


def test_without_height_the_range_over_heights(tmp_path):
    """No sigma_h: error = the largest over the heights, error_range = [smallest, largest]; valid only if valid
    at every height (here M01 is 0.05 at sigma_h 0.5 and 0.3 at 2: invalid at one height -> not valid)."""
    a = _write_atlas(tmp_path / "a.npz", lambda i: 0.3 if (i[2] == 1 and i[5] == 1) else None)
    ans = acc.accuracy(math.radians(40), 0.1, atlas=a)
    m01 = ans["elements"]["M01"]
    assert m01["error"] == pytest.approx(0.3) and m01["error_range"] == pytest.approx([0.05, 0.3])
    assert m01["valid"] is None and "height" in m01["reason"]


@pytest.mark.parametrize("n, k, nearest, parts", [
    (None, None, "PEC", ["PEC"]), (1.5, 0.0, "glass", ["glass"]), (1.5, 15.0, "Al_x", ["Al_x"]),
    (0.8, 4.0, "Au_x", ["Al_x", "Au_x"])])
def test_index_families(atlas, n, k, nearest, parts):
    """A conductor between two atlas conductors (along 1/|eta|) is interpolated between them; a dielectric near
    n = 1.5 is the glass; the nearest material is named."""
    ans = acc.accuracy(math.radians(40), 0.1, n, k, sigma_h_wl=0.5, atlas=atlas)
    assert ans["status"] == "ok" and ans["material"]["nearest"] == nearest
    assert [m for m, _ in ans["material"]["from"]] == parts


@pytest.mark.parametrize("kwargs, words", [
    (dict(theta_i=math.radians(88)), "theta_i = 88 deg is outside the atlas (0-80 deg)"),
    (dict(rms_slope=0.9), "rms_slope = 0.9 is outside the atlas (0.1-0.3)"),
    (dict(sigma_h_wl=0.05), "sigma_h / lambda = 0.05 is outside the atlas"),
    (dict(n=3.0, k=0.5), "outside the atlas's conductors"),
])
def test_unknown_outside_with_the_reason(atlas, kwargs, words):
    q = dict(theta_i=math.radians(40), rms_slope=0.2)
    q.update(kwargs)
    ans = acc.accuracy(q.pop("theta_i"), q.pop("rms_slope"), atlas=atlas, **q)
    assert ans["status"] == "unknown" and words in ans["reason"]
    assert all(e["valid"] is None for e in ans["elements"].values())


def test_cheapest_adequate_variant(tmp_path):
    """smith/none (3e-7 s) fails M22 at every node; vgroove/paper (5e-7 s) is adequate: it is recommended."""
    a = _write_atlas(tmp_path / "a.npz", lambda i: 0.4 if (i[4] == 1 and i[5] == 3) else None)
    ans = acc.accuracy(math.radians(40), 0.2, sigma_h_wl=1.0, atlas=a)
    assert ans["recommended"]["method"] == "model"
    assert (ans["recommended"]["shadowing"], ans["recommended"]["diffuse"]) == ("vgroove", "paper")


@pytest.mark.parametrize("argv, words", [
    (["--theta-i", "x", "--rms-slope", "0.2"], "argument --theta-i: invalid float value"),
    (["--theta-i", "30"], "the following arguments are required: --rms-slope"),
    (["--theta-i", "95", "--rms-slope", "0.2"], "theta_i must be finite and in [0, 1.5708]"),
    (["--theta-i", "30", "--rms-slope", "0.2", "--k", "3"], "k=3.0 needs n"),
    (["--theta-i", "30", "--rms-slope", "-1"], "rms_slope must be finite and in (0"),
])
def test_cli_errors_are_one_line(atlas, argv, words, capsys):
    assert main(["accuracy", *argv, "--atlas", str(atlas.path)]) == 2
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and err.startswith("hyde-bsdf accuracy: error:") and words in err


def test_cli_json(atlas, capsys):
    assert main(["accuracy", "--theta-i", "40", "--rms-slope", "0.1", "--sigma-h-wl", "0.5", "--json",
                 "--atlas", str(atlas.path)]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["elements"]["M00_dB"]["valid"] is True and out["recommended"]["method"] == "model"


@pytest.fixture(scope="module")
def small_cell():
    """A real atlas cell, small: PEC, rms slope 0.3, sigma_h 1 lambda (ell 4.7 lambda: geometric optics), 3
    partitions of 100 lambda, theta_i 20 and 60 deg (~1 CPU s)."""
    from hyde_bsdf.mom import atlas as runs

    task = dict(key="test", rms_slope=0.3, height_wl=1.0, material="PEC", n=None, k=None,
                theta_i_deg=[20.0, 60.0], theta_r_step_deg=0.5, partitions=3, min_partitions=2, cap_s=1e9,
                corr_length_wl=math.sqrt(2.0) / 0.3, partition_wl=100.0, pts_per_wl=10.0, seed=5)
    return runs.run_task(task)


def test_cell_m11_error_is_the_models_diffuse_share(small_cell):
    """On a 1-D surface the exact M11/M00 is 1; the model's is its specular share, so M11's error in the specular
    window is -(diffuse / total) of the 1-D model there, which model1d gives independently (to 1e-6)."""
    from hyde_bsdf.mom import atlas_errors as ae
    from hyde_bsdf.mom.model1d import mueller_sigma

    res = ae.cell_errors(small_cell, [("vgroove", "paper")])
    tr = np.radians(np.arange(-2.5, 2.51, 0.5))
    full = mueller_sigma(np.radians([[20.0]]), np.radians(20.0) + tr, 0.3, None, 0.0, "vgroove", "paper")["M00"]
    spec = mueller_sigma(np.radians([[20.0]]), np.radians(20.0) + tr, 0.3, None, 0.0, "vgroove", "none")["M00"]
    e, r = ae.ELEMENTS.index("M11"), ae.REGIONS.index("specular")
    assert res["signed"][0, 0, e, r] == pytest.approx(np.mean(spec / full - 1.0), abs=2e-3)   # smoothing: 2e-3


def test_cell_model_within_db_of_exact_em_in_geometric_optics(small_cell):
    """The paper's model (V-groove, Eq. 17's diffuse term) on a GO surface at 20 deg: M00 within 1.5 dB of the MoM
    over the lobe (rms; 3 partitions' jackknife se beside it); M22/M00 a PEC's -1 within 0.05 near specular, but
    not over the whole lobe, whose forward wing (theta_r 50-80 deg) multiple scattering takes to -0.8 ... +0.2
    (a power-weighted rms error above the default tolerance 0.1: what the model's single bounce cannot give, with or
    without its diffuse term)."""
    from hyde_bsdf.mom import atlas_errors as ae

    res = ae.cell_errors(small_cell, [("vgroove", "paper"), ("vgroove", "none")])
    lobe, spec, m22 = ae.REGIONS.index("lobe"), ae.REGIONS.index("specular"), ae.ELEMENTS.index("M22")
    assert res["status"].tolist() == [0, 0]
    assert res["error"][0, 0, 0, lobe] < 1.5 and 0 < res["se"][0, 0, 0, lobe] < 2.0      # 3 partitions: se ~1 dB
    assert res["error"][0, 0, m22, spec] < 0.05
    assert res["error"][0, 0, m22, lobe] > 0.1 and res["error"][0, 1, m22, lobe] > 0.1


def test_model1d_reciprocal_diffuse_is_reciprocal_and_conserves_energy():
    """The 1-D reciprocal diffuse term: f_d(a, b) = f_d(b, a), and int f_d cos(theta_r) d theta_r = 1 - rho_s(a)
    (so a PEC's energy still closes), to 1e-9 / 1e-4 (rho is tabulated on 401 angles)."""
    from hyde_bsdf.mom import model1d

    t = np.linspace(-np.pi / 2, np.pi / 2, 2001)
    fd = model1d.brdf_diffuse(np.radians([[40.0]]), 0.4, "smith", "reciprocal", t)
    assert np.trapezoid(fd * np.cos(t), t)[0] == pytest.approx(1 - model1d.dhr_specular(np.radians(40.0), 0.4,
                                                                                        "smith"), abs=1e-4)
    a = model1d.brdf_diffuse(np.radians(30.0), 0.4, "vgroove", "reciprocal", np.radians(70.0))
    b = model1d.brdf_diffuse(np.radians(70.0), 0.4, "vgroove", "reciprocal", np.radians(30.0))
    assert a == pytest.approx(b, rel=1e-9)


def test_mom_says_its_estimate_before_a_long_run(monkeypatch):
    """A run expected to exceed cost.REPORT_SECONDS says its estimated time and memory first (here the threshold is
    lowered to 0 s for a run of milliseconds); estimate() gives the same line without solving."""
    from hyde_bsdf import mom
    from hyde_bsdf.mom import cost

    monkeypatch.setattr(cost, "REPORT_SECONDS", 0.0)
    lines = []
    mom.scatter(40.0, 2, 0.3, 2.0, [30.0], [30.0], pts_per_wl=8, executor=mom.SerialExecutor(), progress=lines.append)
    assert lines and lines[0].startswith("estimated ~") and "2 partition(s) of 160 unknowns" in lines[0]
    est = mom.estimate(40.0, 2, 0.3, 2.0, [30.0], [30.0], pts_per_wl=8, workers=1)
    assert est["line"].split(":")[1] == lines[0].split(":")[1] and est["memory_bytes"] > 0


def test_gather_hands_each_result_over_as_it_finishes():
    """gather(on_result=): the atlas's checkpoints are written there, one call per task with its index."""
    from hyde_bsdf.mom import SerialExecutor
    from hyde_bsdf.mom.gather import gather

    seen = []
    assert gather(SerialExecutor(), abs, [-1, -2, -3], on_result=lambda i, r: seen.append((i, r))) == [1, 2, 3]
    assert sorted(seen) == [(0, 1), (1, 2), (2, 3)]


def test_fit_height_options_are_checked_before_the_fit(tmp_path, capsys):
    """hyde-bsdf fit --sigma-h-um on data without a wavelength column and without --wavelength-nm: one line
    saying what is missing, exit 2, before any fitting; two heights at once: refused before the file is read."""
    data = tmp_path / "m.csv"
    data.write_text("theta_i_deg,theta_r_deg,phi_deg,M22,M22_sigma\n20,20,180,-0.99,0.01\n40,40,180,-0.97,0.01\n")
    assert main(["fit", str(data), "--sigma-h-um", "1"]) == 2
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and "--sigma-h-um needs the wavelength" in err
    assert main(["fit", str(tmp_path / "missing.csv"), "--sigma-h-um", "1", "--sigma-h-wl", "2"]) == 2
    assert "give --sigma-h-wl or --sigma-h-um" in capsys.readouterr().err
