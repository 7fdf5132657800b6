"""The model's pluggable terms: one record per shadowing function and per diffuse term.

Like SCATMECH's ``Shadow_Function`` passed to its facet model, each term is one object that
carries its name, its functions and its rules, and every user reads it from here: the evaluator
(:mod:`hyde_bsdf.model.evaluator`), the DHR quadrature and table (:mod:`hyde_bsdf.model.dhr`),
the fits and the export (:mod:`hyde_bsdf.fit`), the command line's choices, the MoM's 1-D model
(:mod:`hyde_bsdf.mom.model1d`) and the Mitsuba plugin (which keys its own Dr.Jit implementation
of each term by the record's name: the evaluator and the plugin are independent derivations that
share data -- names, rules, the DHR table -- never formula code).

Shadowing terms (:data:`SHADOWING_TERMS`): ``vgroove`` (paper Eq. 12), ``smith``, ``none``.
Diffuse terms (:data:`DIFFUSE_TERMS`): ``paper`` (Eq. 17), ``reciprocal``, ``none``, ``lambertian``
(a free albedo ``diffuse_reflectance``: not the paper's, its size not tied to the roughness).

The rule (one statement, :func:`check_pair`): a diffuse term that divides by 1 - rho_avg
(``reciprocal``) needs a shadowing term whose specular DHR stays <= 1; without shadowing rho
exceeds 1 at grazing incidence and 1 - rho_avg is not positive.

Adding a term is adding one record to the tuple below (and, for the plugin, its Dr.Jit
implementation under the same name; a record without one is refused there by name).  A term
with parameters of its own lists them in ``parameters`` (names of registry ranges in
:mod:`hyde_bsdf.model.parameters`); its functions then take them as keywords.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

from hyde_bsdf.errors import UsageError, shorten
from hyde_bsdf.model import diffuse as _diffuse
from hyde_bsdf.model import shadowing as _shadowing

__all__ = ["ShadowingTerm", "DiffuseTerm", "SHADOWING_TERMS", "DIFFUSE_TERMS", "SHADOWING", "DIFFUSE",
           "PARAMETER_DEFAULTS", "RENDER_DEFAULT", "shadowing_term", "diffuse_term", "check_pair", "allowed", "term_arguments",
           "model_size"]


@dataclass(frozen=True)
class ShadowingTerm:
    """A shadowing/masking function G of the specular term (Eq. 6).

    ``g``: G on the 2-D surface, ``g(cos_alpha, cos_beta, cos_i, cos_r, rms_slope)`` (the evaluator);
    ``g_plane``: G in the plane of a 1-D surface, ``g_plane(theta_i, theta_r, rms_slope)`` (the
    MoM's 1-D model); ``dhr_weight``: Eq. 14's integrand in facet-slope space,
    ``w(u, r2, cos_i, rms_slope)``, integrated with ``dhr_order`` Gauss-Legendre nodes (outer, inner)
    per smooth piece for the shipped table; ``dhr_kinks_p``/``dhr_kinks_q``: where that integrand has
    kinks (the quadrature splits there), or None; ``dhr_bounded``: the specular DHR of a PEC stays <= 1.
    """
    name: str
    summary: str
    g: Callable
    g_plane: Callable
    dhr_weight: Callable
    dhr_order: tuple
    dhr_bounded: bool = True
    dhr_kinks_p: Callable | None = None
    dhr_kinks_q: Callable | None = None
    #: model selection: 1 if the term adds to the model (0 for "none"), tried in increasing rank
    adds: int = 1
    rank: int = 1


@dataclass(frozen=True)
class DiffuseTerm:
    """An unpolarized diffuse term F^d_00 (Eqs. 16-17 and variants), or "none".

    ``f00(h, theta_i, theta_r, M00, **params)``: the term on a hemisphere ``h``
    (:mod:`hyde_bsdf.model.diffuse`), the same function on the 2-D surface (the evaluator) and in
    the plane (the 1-D model); None for no diffuse term.  ``reads_dhr``: whether it reads the
    specular DHR table (the plugin loads the table only then).  ``needs_bounded_dhr``: it divides by
    1 - rho_avg, so it needs a shadowing term with ``dhr_bounded``.  ``parameters``: names of its own
    parameters (registry ranges), passed to ``f00`` as keywords.
    """
    name: str
    summary: str
    f00: Callable | None
    reads_dhr: bool = True
    needs_bounded_dhr: bool = False
    parameters: tuple = ()
    adds: int = 1
    rank: int = 1

    @property
    def present(self) -> bool:
        """False for "none" (no diffuse lobe)."""
        return self.f00 is not None


SHADOWING_TERMS = (
    ShadowingTerm("vgroove", "Torrance-Sparrow V-groove, paper Eq. 12", _shadowing.g_vgroove,
                  _shadowing.g_vgroove_plane, _shadowing.w_vgroove, (10, 6),
                  dhr_kinks_p=_shadowing.vgroove_kinks_p, dhr_kinks_q=_shadowing.vgroove_kinks_q, rank=2),
    # Smith's G1(theta_r) has a steep layer near the horizon that wants more nodes
    ShadowingTerm("smith", "Smith G1(i) G1(r) of the Beckmann distribution", _shadowing.g_smith,
                  _shadowing.g_smith_plane, _shadowing.w_smith, (20, 12), rank=1),
    ShadowingTerm("none", "G = 1 (Priest-Germer); the specular DHR exceeds 1 at grazing incidence",
                  _shadowing.g_none, _shadowing.g_none_plane, _shadowing.w_none, (20, 12),
                  dhr_bounded=False, adds=0, rank=0),
)

DIFFUSE_TERMS = (
    DiffuseTerm("paper", "paper Eq. 17: (1 - rho(theta_in)) M00 / pi (not reciprocal)", _diffuse.f00_paper, rank=1),
    DiffuseTerm("reciprocal", "(1 - rho(theta_i))(1 - rho(theta_o)) M00 / (pi (1 - rho_avg)), reciprocal",
                _diffuse.f00_reciprocal, needs_bounded_dhr=True, rank=2),
    DiffuseTerm("none", "specular lobe only", None, reads_dhr=False, adds=0, rank=0),
    DiffuseTerm("lambertian", "diffuse_reflectance / pi: a Lambertian part with its own albedo (not the paper's)",
                _diffuse.f00_lambertian, reads_dhr=False, parameters=("diffuse_reflectance",), rank=3),
)

#: the names, in the registry's order (the first is the default of the evaluator and the fits: the paper's model)
SHADOWING = tuple(t.name for t in SHADOWING_TERMS)
DIFFUSE = tuple(t.name for t in DIFFUSE_TERMS)
#: (shadowing, diffuse) of the renderers' default material -- the ``hyde`` plugin and ``hyde-bsdf export``
#: (a table Mitsuba renders): the paper's V-groove with the reciprocal diffuse term, whose white-furnace albedo
#: stays <= 1 in both transport modes at every roughness and angle; the paper's Eq. 17 term returns up to
#: 1.94x the light of the furnace in a path tracer (docs/plugin.md, "Energy: the default material";
#: hyde_bsdf/validation/furnace.py)
RENDER_DEFAULT = ("vgroove", "reciprocal")
_BY_NAME = {"shadowing": {t.name: t for t in SHADOWING_TERMS}, "diffuse": {t.name: t for t in DIFFUSE_TERMS}}


def _lookup(kind, name):
    table = _BY_NAME[kind]
    if not isinstance(name, str) or name not in table:
        raise UsageError(f"{kind} must be one of {tuple(table)}, got {shorten(name)}")
    return table[name]


def shadowing_term(name) -> ShadowingTerm:
    """The record of a shadowing name (one of :data:`SHADOWING`); UsageError naming the choices otherwise."""
    return name if isinstance(name, ShadowingTerm) else _lookup("shadowing", name)


def diffuse_term(name, booleans=True) -> DiffuseTerm:
    """The record of a diffuse name (one of :data:`DIFFUSE`); with ``booleans`` (the evaluator's
    spelling) True is "paper" and False or None "none".  UsageError naming the choices otherwise."""
    if isinstance(name, DiffuseTerm):
        return name
    if booleans and (name is True or name is False or name is None):
        return _BY_NAME["diffuse"]["paper" if name else "none"]
    try:
        return _lookup("diffuse", name)
    except UsageError:
        if booleans:
            raise UsageError(f"diffuse must be True, False or one of {DIFFUSE}, got {shorten(name)}") from None
        raise


def allowed(shadowing, diffuse) -> bool:
    """Whether the pair of terms is a model (the rule of :func:`check_pair`)."""
    return not (diffuse_term(diffuse).needs_bounded_dhr and not shadowing_term(shadowing).dhr_bounded)


def check_pair(shadowing, diffuse, booleans=True) -> tuple:
    """(shadowing record, diffuse record) of two names, checked against the rule (module docstring).

    UsageError naming the parameter for an unknown name, and the pair when the rule refuses it."""
    s, d = shadowing_term(shadowing), diffuse_term(diffuse, booleans)
    if not allowed(s, d):
        ok = [t.name for t in SHADOWING_TERMS if t.dhr_bounded]
        raise UsageError(f"diffuse={d.name!r} needs shadowing={' or '.join(map(repr, ok))}; with "
                         f"shadowing={s.name!r} the specular DHR exceeds 1 and (1 - rho_avg) is not positive")
    return s, d


#: the value a term parameter takes when it is not given (Mitsuba's diffuse_reflectance default, 0.5)
PARAMETER_DEFAULTS = {"diffuse_reflectance": 0.5}


def term_arguments(term, **given) -> dict:
    """The keyword arguments of ``term``'s own parameters (checked against their registry ranges,
    :data:`PARAMETER_DEFAULTS` where not given).  ``given``: name -> value or None; a value for a
    parameter the term does not have is refused, naming the term that has it."""
    from hyde_bsdf.model import parameters

    term = diffuse_term(term)
    for name, value in given.items():
        if value is not None and name not in term.parameters:
            owners = [t.name for t in DIFFUSE_TERMS if name in t.parameters]
            raise UsageError(f"{name} is a parameter of diffuse={' or '.join(map(repr, owners))}, not of "
                             f"diffuse={term.name!r}")
    return {name: getattr(parameters, name.upper()).check(given.get(name) if given.get(name) is not None
                                                          else PARAMETER_DEFAULTS[name], name)
            for name in term.parameters}


def model_size(shadowing, diffuse, free_parameters: int) -> int:
    """Free parameters + 1 per term the model adds (a shadowing function, a diffuse term): model
    selection's size (a term's own fitted parameters are among ``free_parameters``)."""
    return free_parameters + shadowing_term(shadowing).adds + diffuse_term(diffuse).adds
