"""The package's layers, as the folders hold them: no import runs up the layers.

    io  ->  model  ->  {mitsuba, mom, fit}  ->  render  ->  inverse  ->  app  ->  validation

A module may import from its own folder and from folders to its left; ``mitsuba``, ``mom`` and
``fit`` are independent of one another; ``errors``, ``progress``, ``resources`` and ``options`` may be
imported from anywhere and import nothing of the package but ``errors``.  Every ``import`` statement counts, the lazy ones inside
functions too (they are parsed, not run).  The bottom layer, ``io``, imports only the standard
library, NumPy and (lazily) the file-format packages; the library below ``app`` does no argparse
and no plotting.  ``validation`` (the validation scripts, run by ``hyde-bsdf validate`` as child
processes) is the top layer: nothing else imports it.  This test reads the source only: it checks the rule of
docs/architecture.md in a fraction of a second.
"""
from __future__ import annotations

import ast
import sys
from pathlib import Path

import pytest

PACKAGE = Path(__file__).resolve().parent.parent / "hyde_bsdf"

#: layer of each top-level part of the package; None: importable from anywhere
LAYER = {"errors": None, "progress": None, "resources": None, "options": None, "io": 0, "model": 1, "mitsuba": 2,
         "mom": 2, "fit": 2, "render": 3, "inverse": 4, "app": 5, "validation": 6}
#: ``from hyde_bsdf import NAME`` for the package's own lazy names: where NAME lives
ROOT_NAMES = {"register": "mitsuba", "pbrdf": "model", "dhr_specular_pec": "model", "rms_slope_from": "model",
              "alpha_from_rms_slope": "model", "rms_slope_from_alpha": "model"}
#: third-party packages the io layer may use (the last three only inside the function that needs them)
IO_THIRD_PARTY = {"numpy", "OpenEXR", "PIL", "mitsuba", "drjit"}
#: what only the application (``app``) and the validation scripts above it may import
APP_ONLY = {"argparse", "matplotlib"}


def _part(module: str) -> str | None:
    """The top-level part of ``hyde_bsdf.x.y`` (``x``), or None for another package."""
    head, _, rest = module.partition(".")
    if head != "hyde_bsdf":
        return None
    return rest.partition(".")[0] or ""


def _imports(path: Path, root: Path):
    """(line, imported module, [names]) of every import statement in ``path``, nested ones included."""
    tree = ast.parse(path.read_text(encoding="utf-8"), str(path))
    package = ".".join(path.relative_to(root.parent).with_suffix("").parts)
    if path.name == "__init__.py":
        package += ".__init__"
    for node in sorted(ast.walk(tree), key=lambda n: getattr(n, "lineno", 0)):
        if isinstance(node, ast.Import):
            for alias in node.names:
                yield node.lineno, alias.name, []
        elif isinstance(node, ast.ImportFrom):
            module = node.module or ""
            if node.level:                                 # relative: resolve against this module
                base = package.split(".")[:-node.level]
                module = ".".join(base + ([module] if module else []))
            yield node.lineno, module, [alias.name for alias in node.names]


def _targets(module: str, names: list) -> list[str]:
    """The parts of the package an import reaches (``from hyde_bsdf import mom`` reaches mom)."""
    part = _part(module)
    if part is None:
        return []
    if part:
        return [part]
    return [n if n in LAYER else ROOT_NAMES.get(n, "") for n in names]


def _modules():
    return sorted(p for p in PACKAGE.rglob("*.py") if "__pycache__" not in p.parts)


def _violations(path: Path, root: Path = PACKAGE) -> list[str]:
    rel = path.relative_to(root)
    own = rel.parts[0].removesuffix(".py") if len(rel.parts) > 1 or rel.name != "__init__.py" else ""
    if own == "":                                   # hyde_bsdf/__init__.py: the lazy facade over every part
        return []
    layer = LAYER.get(own)
    out = []
    for line, module, names in _imports(path, root):
        where = f"{rel}:{line}: import of {module}"
        top = module.partition(".")[0]
        if own not in ("app", "validation") and top in APP_ONLY:
            out.append(f"{where}: argparse and plotting belong to hyde_bsdf.app")
        if own == "io" and _part(module) is None and top not in IO_THIRD_PARTY and top not in sys.stdlib_module_names:
            out.append(f"{where}: the io layer imports only the standard library, NumPy and file-format packages")
        for target in _targets(module, names):
            if target == "" or target == own or LAYER.get(target, 0) is None:
                continue
            if target not in LAYER:
                out.append(f"{where}: {target!r} is in no layer (add it to LAYER and docs/architecture.md)")
            elif layer is None:
                out.append(f"{where}: {own}.py must import nothing of the package")
            elif LAYER[target] >= layer:
                out.append(f"{where}: {own} (layer {layer}) may not import {target} (layer {LAYER[target]})")
    return out


def test_every_part_of_the_package_has_a_layer():
    parts = {p.name.removesuffix(".py") for p in PACKAGE.iterdir()
             if (p.is_dir() and (p / "__init__.py").exists()) or (p.suffix == ".py" and p.name != "__init__.py")}
    assert parts - set(LAYER) == set(), "new part of the package without a layer"


@pytest.mark.parametrize("path", _modules(), ids=lambda p: str(p.relative_to(PACKAGE)))
def test_no_import_runs_up_the_layers(path):
    assert _violations(path) == []


def test_the_checker_sees_lazy_imports_and_names_imported_from_the_package(tmp_path):
    """The rule is enforced on what the checker finds: a lazy import inside a function and
    ``from hyde_bsdf import register`` (which lives in mitsuba) are both caught, and so are a
    third-party package and argparse in io."""
    root = tmp_path / "hyde_bsdf"
    (root / "model").mkdir(parents=True)
    (root / "io").mkdir()
    bad = root / "model" / "probe.py"
    bad.write_text("def f():\n    from hyde_bsdf.render import renderer\n\nfrom hyde_bsdf import register\n")
    found = _violations(bad, root)
    assert len(found) == 2 and "render (layer 3)" in found[0] and "mitsuba (layer 2)" in found[1], found
    bad_io = root / "io" / "probe.py"
    bad_io.write_text("import scipy\nimport argparse\nfrom . import atomic\nfrom ..model import checks\n")
    found = _violations(bad_io, root)
    assert len(found) == 3 and "standard library" in found[0] and "argparse" in found[1], found
    assert "model (layer 1)" in found[2], found


#: the infrastructure (issue 34): atomic writes, gates, locks, trust, memory and resources, gather,
#: runtime, signals, errors, progress -- not the file-format readers.  A module that joins it is listed here.
INFRASTRUCTURE = ["errors.py", "progress.py", "resources.py", "io/atomic.py", "io/input_gate.py", "io/output_gate.py",
                  "mom/gather.py", "mom/runtime.py", "app/signals.py"]


def _lines(paths) -> int:
    return sum(len(p.read_text(encoding="utf-8").splitlines()) for p in paths if p.exists())


def test_the_infrastructure_is_smaller_than_the_physics():
    """Issue 34: what guards the work (every line, docstrings and blank lines included) is smaller than
    the model it guards, ``model/``."""
    infrastructure = _lines(PACKAGE / name for name in INFRASTRUCTURE)
    physics = _lines((PACKAGE / "model").glob("*.py"))
    assert infrastructure < physics, f"infrastructure {infrastructure} lines, model/ {physics}"
