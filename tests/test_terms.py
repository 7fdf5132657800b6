"""The term records (model/terms.py) and the index value type (model/index.py).

Physics checked: each diffuse record closes the PEC energy balance of Eq. 15 on the 2-D surface
(the evaluator) and in the plane of a 1-D surface (the MoM's model) with the same function; the one
rule (reciprocal diffuse needs a shadowing term with rho <= 1) is refused identically by every
interface; a term passed as a new record needs no other change in the model; the index's
spellings (paper n - jk, Mitsuba eta + ik, PEC as k -> inf) are one value.  About 2 s.
"""
import math

import numpy as np
import pytest

from hyde_bsdf.errors import UsageError
from hyde_bsdf.model import terms
from hyde_bsdf.model.evaluator import pbrdf
from hyde_bsdf.model.index import PEC, Index
from hyde_bsdf.mom import model1d


def test_names_and_defaults_come_from_the_records():
    assert terms.SHADOWING == ("vgroove", "smith", "none")
    assert terms.DIFFUSE == ("paper", "reciprocal", "none", "lambertian")          # lambertian: issue 30
    assert [t.name for t in terms.SHADOWING_TERMS if not t.dhr_bounded] == ["none"]
    assert [t.name for t in terms.DIFFUSE_TERMS if t.needs_bounded_dhr] == ["reciprocal"]
    assert terms.diffuse_term(True).name == "paper" and terms.diffuse_term(None).name == "none"
    with pytest.raises(UsageError, match="diffuse must be one of"):
        terms.diffuse_term(True, booleans=False)


def _refusals():
    """The rule's refusal as each interface words it (the same message, prefixed by the plugin)."""
    from hyde_bsdf.fit.mueller_fit import check_options
    from hyde_bsdf.fit.pbsdf_export import export_pbsdf
    calls = {
        "evaluator": lambda: pbrdf(0.3, 0.3, math.pi, rms_slope=0.3, pec=True, shadowing="none", diffuse="reciprocal"),
        "fit": lambda: check_options(shadowing="none", diffuse="reciprocal"),
        "export": lambda: export_pbsdf("x.pbsdf", rms_slope=0.3, n=1.5, k=0.0, shadowing="none", diffuse="reciprocal"),
        "1-D model": lambda: model1d.brdf(0.3, 0.3, 0.3, shadowing="none", diffuse="reciprocal"),
    }
    out = {}
    for name, call in calls.items():
        with pytest.raises(UsageError) as info:
            call()
        out[name] = str(info.value)
    return out


def test_the_reciprocal_rule_is_one_message_everywhere():
    """diffuse='reciprocal' with shadowing='none': 1 - rho_avg is not positive; every interface refuses it
    with the rule's own words (model/terms.py: check_pair)."""
    texts = _refusals()
    rule = str(pytest.raises(UsageError, terms.check_pair, "none", "reciprocal").value)
    assert "reciprocal" in rule and "vgroove" in rule and "smith" in rule
    assert all(t == rule for t in texts.values()), texts


@pytest.mark.parametrize("diffuse", ["paper", "reciprocal"])
@pytest.mark.parametrize("shadowing", ["vgroove", "smith"])
def test_each_diffuse_record_closes_the_1d_energy_balance(shadowing, diffuse):
    """1-D Eq. 15 for a PEC: int f_d cos(theta_r) d theta_r = 1 - rho_s(theta_i), the specular DHR in the
    plane, for the same diffuse function the evaluator uses (here on the in-plane hemisphere).
    Tolerance 2e-4: the trapezoid over theta_r and the 200-node average of the reciprocal term."""
    ti = np.radians([0.0, 40.0, 75.0])
    tr = np.linspace(-0.5 * math.pi, 0.5 * math.pi, 4001)
    fd = model1d.brdf_diffuse(ti[:, None], 0.3, shadowing, diffuse, tr[None, :])
    fd = np.broadcast_to(fd, (ti.size, tr.size))
    energy = np.trapezoid(fd * np.cos(tr), tr, axis=1)
    np.testing.assert_allclose(energy, 1.0 - model1d.dhr_specular(ti, 0.3, shadowing), atol=2e-4)


def test_the_paper_term_in_the_plane_is_half_of_one_minus_rho():
    """The paper's 1-D term (Eq. 16 in the plane) is the Lambertian f_d = (1 - rho_s) / 2 exactly."""
    ti = np.radians([10.0, 60.0])
    np.testing.assert_array_equal(model1d.brdf_diffuse(ti, 0.3),
                                  0.5 * (1.0 - model1d.dhr_specular(ti, 0.3)))


def test_a_new_record_plugs_into_the_evaluator_and_the_1d_model_unchanged():
    """A term is one record: a uniform Lambertian of albedo 0.25, passed as a record, gives F00 = 0.25/pi on
    the surface and 0.25/2 in the plane (its hemispherical integral 0.25) with no other code."""
    lam = terms.DiffuseTerm("test_lambert", "albedo 0.25", lambda h, ti, tr, M00: np.broadcast_to(
        0.25 / h.measure, np.broadcast(ti, tr).shape), reads_dhr=False)
    spec = pbrdf(0.4, 0.7, 1.0, rms_slope=0.3, pec=True, diffuse="none")
    F = pbrdf(0.4, 0.7, 1.0, rms_slope=0.3, pec=True, diffuse=lam)
    assert F[0, 0] - spec[0, 0] == pytest.approx(0.25 / math.pi, rel=1e-15)
    f = model1d.brdf(0.4, 0.7, 0.3, diffuse=lam) - model1d.brdf(0.4, 0.7, 0.3, diffuse=False)
    assert f == pytest.approx(0.125, rel=1e-15)


def test_the_lambertian_record_is_its_albedo_on_the_surface_and_in_the_plane():
    """Issue 30's free diffuse part: F00 += diffuse_reflectance / pi on the surface, f_d = albedo / 2 in
    the plane (hemispherical integral = the albedo either way), unpolarized, independent of the
    roughness and the index; the albedo is the record's own parameter (registry range [0, 1]) and a
    term without it refuses it."""
    base = pbrdf(0.4, 0.7, 1.0, rms_slope=0.3, n=0.18, k=3.0, diffuse="none")
    F = pbrdf(0.4, 0.7, 1.0, rms_slope=0.3, n=0.18, k=3.0, diffuse="lambertian", diffuse_reflectance=0.2)
    assert F[0, 0] - base[0, 0] == pytest.approx(0.2 / math.pi, rel=1e-14)
    np.testing.assert_array_equal(F.ravel()[1:], base.ravel()[1:])
    f = model1d.brdf(0.4, 0.7, 0.3, diffuse="lambertian", diffuse_reflectance=0.2) - model1d.brdf(0.4, 0.7, 0.3,
                                                                                                 diffuse=False)
    assert f == pytest.approx(0.1, rel=1e-14)
    with pytest.raises(UsageError, match=r"diffuse_reflectance must be a finite number in \[0, 1\], got 1.5"):
        pbrdf(0.4, 0.7, 1.0, rms_slope=0.3, pec=True, diffuse="lambertian", diffuse_reflectance=1.5)
    with pytest.raises(UsageError, match="diffuse_reflectance is a parameter of diffuse='lambertian'"):
        pbrdf(0.4, 0.7, 1.0, rms_slope=0.3, pec=True, diffuse="paper", diffuse_reflectance=0.2)


def test_the_plugin_refuses_a_record_it_has_no_implementation_for(monkeypatch):
    pytest.importorskip("mitsuba")
    from hyde_bsdf.mitsuba import plugin
    monkeypatch.setitem(terms._BY_NAME["diffuse"], "test_lambert",
                        terms.DiffuseTerm("test_lambert", "", lambda h, ti, tr, M00: 0.0, reads_dhr=False))

    class Props(dict):
        def get(self, key, default=None):
            return dict.get(self, key, default)
    with pytest.raises(UsageError, match="hyde: diffuse='test_lambert' has no Dr.Jit implementation"):
        plugin._read_terms(Props(diffuse="test_lambert"))


def test_one_index_two_spellings_and_the_pec():
    """Gold at 633 nm: Mitsuba 0.18 + 3.0i = the paper's 0.18 - j 3.0; the PEC is k = inf and gives the
    same matrix through pec=True, index=PEC and (1-D model) n=None."""
    gold = Index.from_mitsuba(0.18, 3.0)
    assert (gold.n, gold.k) == (0.18, 3.0) and gold.paper_eta() == complex(0.18, -3.0)
    a = pbrdf(0.3, 0.5, 2.0, rms_slope=0.3, n=0.18, k=3.0)
    np.testing.assert_array_equal(a, pbrdf(0.3, 0.5, 2.0, rms_slope=0.3, index=gold))
    np.testing.assert_array_equal(pbrdf(0.3, 0.5, 2.0, rms_slope=0.3, pec=True),
                                  pbrdf(0.3, 0.5, 2.0, rms_slope=0.3, index=PEC))
    ti, tr = np.radians([[30.0]]), np.radians([10.0, 40.0])
    m_none = model1d.mueller_sigma(ti, tr, 0.3)
    m_pec = model1d.mueller_sigma(ti, tr, 0.3, index=PEC)
    for key in m_none:
        np.testing.assert_array_equal(m_none[key], m_pec[key])
    with pytest.raises(UsageError, match="not both"):
        pbrdf(0.3, 0.5, 2.0, rms_slope=0.3, n=0.18, index=gold)
    with pytest.raises(UsageError, match="k"):
        Index(1.0, -1.0)
    with pytest.raises(UsageError, match="PEC"):
        PEC.mitsuba()


@pytest.mark.parametrize("diffuse", ["paper", "reciprocal", "lambertian", "none"])
def test_the_diffuse_part_has_the_shape_of_its_arguments_for_every_record(diffuse):
    """diffuse_pbrdf returns broadcast(theta_i, theta_r, M00) for every record, also for the paper's
    Eq. 17, whose value reads theta_i only: 12 incidence x 7 reflection angles give 12 x 7 values, each
    row constant along theta_r for the paper's term (exact)."""
    from hyde_bsdf.model.evaluator import diffuse_pbrdf

    ti = np.radians(np.linspace(0.0, 80.0, 12))[:, None]
    tr = np.radians(np.linspace(0.0, 80.0, 7))[None, :]
    f = diffuse_pbrdf(ti, tr, 1.0, 0.3, diffuse, diffuse_reflectance=0.3 if diffuse == "lambertian" else None)
    assert f.shape == (12, 7) and f.flags.writeable
    if diffuse == "paper":
        np.testing.assert_array_equal(f, np.repeat(f[:, :1], 7, axis=1))
