"""Narrow interfaces (issue 34): what a caller of the library meets.

* no function or method in ``hyde_bsdf/`` takes more than :data:`MAX_PARAMETERS` parameters
  (``self``/``cls`` not counted; ``*args`` and ``**settings`` count one each): the settings of a
  long computation are an option record (:class:`hyde_bsdf.options.Options`);
* ``hyde_bsdf.inverse.__all__`` names at most :data:`MAX_INVERSE_NAMES` names: what a user calls;
* the library's messages name parameters, not command-line ``--flags``: only ``hyde_bsdf/app/``
  (whose one table, :data:`hyde_bsdf.app.flags.FLAGS`, maps the names to the flags for the
  command line's messages) spells a flag in a string that is not a docstring.

Source inspection with ``ast`` (no import of the package), a fraction of a second.
"""
from __future__ import annotations

import ast
import re
from pathlib import Path

from conftest import docstring_ids

PACKAGE = Path(__file__).resolve().parent.parent / "hyde_bsdf"
MAX_PARAMETERS = 12
MAX_INVERSE_NAMES = 20
FLAG = re.compile(r"(?<![\w-])--[a-z][a-z0-9-]*")


def _modules():
    return sorted(p for p in PACKAGE.rglob("*.py") if "__pycache__" not in p.parts)


def _parameters(node) -> int:
    a = node.args
    names = [x.arg for x in a.posonlyargs + a.args]
    count = len(names) + len(a.kwonlyargs) + (a.vararg is not None) + (a.kwarg is not None)
    return count - (1 if names and names[0] in ("self", "cls") else 0)


def test_no_function_takes_more_than_twelve_parameters():
    wide = [f"{p.relative_to(PACKAGE)}:{n.lineno} {n.name} ({_parameters(n)})" for p in _modules()
            for n in ast.walk(ast.parse(p.read_text(encoding="utf-8")))
            if isinstance(n, (ast.FunctionDef, ast.AsyncFunctionDef)) and _parameters(n) > MAX_PARAMETERS]
    assert wide == []


def test_inverse_exports_what_a_user_needs():
    tree = ast.parse((PACKAGE / "inverse" / "__init__.py").read_text(encoding="utf-8"))
    names = next(ast.literal_eval(n.value) for n in tree.body if isinstance(n, ast.Assign)
                 and any(isinstance(t, ast.Name) and t.id == "__all__" for t in n.targets))
    assert len(names) <= MAX_INVERSE_NAMES, names
    imported = {a.asname or a.name for n in tree.body if isinstance(n, ast.ImportFrom) for a in n.names}
    assert set(names) <= imported and imported <= set(names), "import only what __all__ names"


def _flags_in_strings(path: Path) -> list[str]:
    tree = ast.parse(path.read_text(encoding="utf-8"))
    skip = docstring_ids(tree)
    return [f"{path.name}:{n.lineno}: {m}" for n in ast.walk(tree)
            if isinstance(n, ast.Constant) and isinstance(n.value, str) and id(n) not in skip
            for m in FLAG.findall(n.value)]


def test_library_messages_name_parameters_not_flags():
    found = [f"{p.parent.name}/{hit}" for p in _modules() if p.relative_to(PACKAGE).parts[0] not in ("app", "validation")
             for hit in _flags_in_strings(p)]
    assert found == []


def test_the_checks_see_what_they_look_for(tmp_path):
    """The rules are enforced on what the checks find: a flag in an f-string (not a docstring), a
    wide signature."""
    probe = tmp_path / "probe.py"
    probe.write_text('def f(a, b, *c, d, **e):\n    """Use --spp here."""\n    raise ValueError(f"lower --spp {a}")\n')
    tree = ast.parse(probe.read_text())
    assert _parameters(tree.body[0]) == 5
    assert _flags_in_strings(probe) == ["probe.py:3: --spp"]
