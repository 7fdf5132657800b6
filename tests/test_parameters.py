"""The parameter registry (``hyde_bsdf.model.parameters``) is the one definition of every
parameter range, and every interface reads it.

Checked: a source scan of ``hyde_bsdf/`` finds no range literal for rms_slope, alpha, the index
(n, eta, k) or alpha_sample outside the registry (comparisons of those names against numbers,
number pairs bound to those names or to *RANGE*/*BOUNDS*, range defaults, "[lo, hi]" texts in
messages); the evaluator, the plugin, the MoM model, both fits and the inverse accept exactly
the registry's range; the conversions alpha = sqrt(2) rms_slope and eta_paper = n - jk are
inverse pairs.
"""
import ast
import math
import re
from pathlib import Path

import pytest
from conftest import docstring_ids, library_modules

import hyde_bsdf
from hyde_bsdf.model import parameters as P

PACKAGE = Path(hyde_bsdf.__file__).parent
REGISTRY = PACKAGE / "model" / "parameters.py"
#: names whose numeric bounds are parameter ranges
PARAM_NAME = re.compile(r"(rms|slope|alpha|rough|^eta$|^n$|^k$|^n0$|^k0$|index)", re.I)
RANGE_NAME = re.compile(r"(range|bounds)", re.I)
#: every range value the registry defines, and the four values the issue found in seven places
#: ([0, 1], the range of every fraction -- diffuse_reflectance's too -- names no one parameter: not counted)
KNOWN_PAIRS = ({(r.lo, r.hi) for r in vars(P).values() if isinstance(r, P.Range)} - {(0.0, 1.0)}) | {
    (1e-4, 100.0), (1e-4, 50.0), (0.01, 3.0), (0.011, 2.9)}
PAIR_TEXT = re.compile(r"\[\s*([0-9.eE+-]+)\s*,\s*([0-9.eE+-]+)\s*\]")
#: numbers that are not bounds (a 0 lower bound of a non-negative quantity, unit factors)
NOT_BOUNDS = {0.0, 1.0, -1.0}


def _number(node):
    """The value of a numeric literal, ``-literal`` or ``SQRT2 * literal``; None otherwise."""
    if isinstance(node, ast.Constant) and isinstance(node.value, (int, float)) and not isinstance(node.value, bool):
        return float(node.value)
    if isinstance(node, ast.UnaryOp) and isinstance(node.op, ast.USub):
        v = _number(node.operand)
        return None if v is None else -v
    if isinstance(node, ast.BinOp) and isinstance(node.op, ast.Mult) and "SQRT2" in (_name(node.left),
                                                                                      _name(node.right)):
        return _number(node.right) if _number(node.left) is None else _number(node.left)
    return None


def _name(node) -> str:
    if isinstance(node, ast.Name):
        return node.id
    if isinstance(node, ast.Attribute):
        return node.attr
    if isinstance(node, ast.Subscript):
        return _name(node.value) + "[" + (_name(node.slice) if not isinstance(node.slice, ast.Constant)
                                          else str(node.slice.value)) + "]"
    if isinstance(node, ast.Call):
        return _name(node.func) + "(" + ",".join(_name(a) for a in node.args) + ")"
    return ""


def _pair(node):
    if isinstance(node, (ast.Tuple, ast.List)) and len(node.elts) == 2:
        values = [_number(e) for e in node.elts]
        if None not in values:
            return tuple(values)
    return None


def range_literals(source: str):
    """(line, what) of each range literal for a model parameter in ``source``."""
    tree = ast.parse(source)
    docs = docstring_ids(tree)
    found = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Compare):
            operands = [node.left, *node.comparators]
            names = [_name(o) for o in operands if _number(o) is None]
            # a bare n or k compared with an integer is a count (matrix size), not an index bound
            counts = all(n in ("n", "k") for n in names)
            numbers = [_number(o) for o in operands if _number(o) is not None and _number(o) not in NOT_BOUNDS
                       and not (counts and isinstance(getattr(o, "value", None), int))]
            if numbers and any(PARAM_NAME.search(n) for n in names):
                found.append((node.lineno, f"comparison of {names} with {numbers}"))
        elif isinstance(node, ast.Assign):
            pair = _pair(node.value)
            targets = [_name(t) for t in node.targets]
            if pair and (any(PARAM_NAME.search(t) for t in targets)
                         or (pair in KNOWN_PAIRS and any(RANGE_NAME.search(t) for t in targets))):
                found.append((node.lineno, f"{targets} = {pair}"))
        elif isinstance(node, ast.Dict):
            for key, value in zip(node.keys, node.values):
                key_text = key.value if isinstance(key, ast.Constant) and isinstance(key.value, str) else ""
                pairs = [_pair(value)] + ([_pair(e) for e in value.elts] if isinstance(value, ast.Tuple) else [])
                if PARAM_NAME.search(key_text) and any(p in KNOWN_PAIRS for p in pairs if p):
                    found.append((node.lineno, f"{key_text!r}: {[p for p in pairs if p]}"))
        elif isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)) and PARAM_NAME.search(node.name):
            args = node.args.args[-len(node.args.defaults):] if node.args.defaults else []
            for arg, default in zip(args, node.args.defaults):
                if arg.arg in ("lo", "hi") and _number(default) is not None:
                    found.append((node.lineno, f"def {node.name}({arg.arg}={_number(default)})"))
        elif isinstance(node, ast.Constant) and isinstance(node.value, str) and id(node) not in docs:
            for a, b in PAIR_TEXT.findall(node.value):
                try:
                    pair = (float(a), float(b))
                except ValueError:
                    continue
                if pair in KNOWN_PAIRS:
                    found.append((node.lineno, f"text {node.value[:60]!r}"))
    return found


def test_no_range_literal_outside_the_registry():
    offenders = []
    for path in library_modules(PACKAGE):
        if path == REGISTRY:
            continue
        for line, what in range_literals(path.read_text()):
            offenders.append(f"{path.relative_to(PACKAGE)}:{line}: {what}")
    assert offenders == [], "range literals outside hyde_bsdf/model/parameters.py:\n" + "\n".join(offenders)


@pytest.mark.parametrize("source", [
    "def f(rms_slope):\n    if not 1e-4 <= rms_slope <= 50.0:\n        raise ValueError('x')\n",
    "RMS_RANGE = (1e-4, 50.0)\n",
    "BOUNDS = {'n': (0.0, 1e3)}\n",
    "X = {'alpha': (('.alpha.data',), (SQRT2 * 0.011, SQRT2 * 2.9))}\n",
    "def check_rms_slope(s, lo=1e-4, hi=50.0):\n    pass\n",
    "def f(n, k):\n    if n > 1e3 or k > 1e3:\n        pass\n",
    "def f(s):\n    raise ValueError(f'rms_slope must be in [1e-4, 50], got {s}')\n",
], ids=["comparison", "tuple", "dict", "scaled", "default", "index", "message"])
def test_the_scan_finds_each_kind_of_range_literal(source):
    """The scan itself: each spelling the issue found in the package is caught."""
    assert range_literals(source), source


def test_the_scan_ignores_docstrings_and_non_parameters():
    source = ('def f(x):\n    """rms_slope in [1e-4, 50]."""\n    if x > 3.0:\n        return (0.01, 3.0)\n'
              '    return x\n')
    assert range_literals(source) == []


def test_each_interface_accepts_the_registry_range():
    """Evaluator, MoM model, plugin constants, fits and inverse box: the same [1e-4, 50]."""
    from hyde_bsdf.fit import mueller_fit, pbsdf_fit
    from hyde_bsdf.inverse import scalar
    from hyde_bsdf.model.evaluator import pbrdf
    from hyde_bsdf.mom import model1d
    lo, hi = P.RMS_SLOPE
    assert (lo, hi) == (1e-4, 50.0)
    for s in (lo, hi):
        assert math.isfinite(pbrdf(0.3, 0.3, math.pi, rms_slope=s, n=1.5, k=0.0)[0, 0])
        assert math.isfinite(float(model1d.brdf(0.3, 0.3, s)))
    for s in (lo * (1 - 1e-9), hi * (1 + 1e-9)):
        with pytest.raises(ValueError, match=r"rms_slope .*\[0.0001, 50\]"):
            pbrdf(0.3, 0.3, math.pi, rms_slope=s, n=1.5, k=0.0)
        with pytest.raises(ValueError, match=r"rms_slope"):
            model1d.brdf(0.3, 0.3, s)
    assert mueller_fit.BOUNDS["rms_slope"] == pbsdf_fit.BOUNDS["rms_slope"] == scalar.RANGES["rms_slope"] == (lo, hi)
    assert P.DHR_TABLE_RMS_SLOPE.lo <= lo and P.DHR_TABLE_RMS_SLOPE.hi > hi   # the table covers it, 50 interior


def test_fit_result_at_the_range_edge_loads_without_a_refusal_warning():
    """The fit no longer warns "the plugin will refuse it" for a value the plugin accepts (40)."""
    import warnings
    from hyde_bsdf.fit.mueller_fit import FitResult
    result = FitResult.__new__(FitResult)
    result.params = {"n": 1.5, "k": 0.0, "rms_slope": 40.0}
    result.diffuse, result.shadowing = "paper", "vgroove"
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        d = result.plugin_dict()
    assert d["rms_slope"] == 40.0 and P.RMS_SLOPE.contains(d["rms_slope"])


@pytest.mark.parametrize("s", [1e-4, 0.3, 50.0])
def test_alpha_and_rms_slope_convert_both_ways(s):
    """Beckmann alpha = 2 sigma_h / ell = sqrt(2) rms_slope (conventions.md)."""
    a = P.alpha_from_rms_slope(s)
    assert a == pytest.approx(math.sqrt(2) * s, rel=1e-15)
    assert P.rms_slope_from_alpha(a) == pytest.approx(s, rel=1e-15)
    assert P.ALPHA.contains(a)


def test_paper_and_mitsuba_index_are_the_same_numbers():
    """Gold at 633 nm, Mitsuba 0.18 + 3.0i, is the paper's eta = 0.18 - j 3.0: one Index, two spellings."""
    from hyde_bsdf.model.index import PEC, Index
    gold = Index.from_mitsuba(0.18, 3.0)
    assert gold.paper_eta() == complex(0.18, -3.0)
    assert gold.mitsuba() == {"eta": 0.18, "k": 3.0}
    assert PEC.is_pec and PEC.paper_eta() is None and not gold.is_pec


def test_spellings_name_each_interface_and_are_unambiguous():
    from hyde_bsdf.fit import mueller_fit
    from hyde_bsdf.inverse import scalar
    assert mueller_fit.PARAMETERS == P.FIT_PARAMETERS == P.SPELLINGS["fit"] == ("n", "k", "rms_slope")
    assert scalar.PARAMETERS == P.INVERSE_PARAMETERS == P.SPELLINGS["inverse"] == ("rms_slope", "eta", "k")
