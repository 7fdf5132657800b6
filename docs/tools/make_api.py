"""Write docs/api.md (every public name of the package, each module's ``__all__``, with its
signature and the first line of its docstring) and the table of test files in
docs/validation.md (between ``<!-- BEGIN tests -->`` and ``<!-- END tests -->``: each file with
the first paragraph of its docstring), read from the source (no imports, no Mitsuba).

    .venv/bin/python docs/tools/make_api.py          # rewrite both
    .venv/bin/python docs/tools/make_api.py --check  # exit 1 if either is out of date

``tests/test_docs.py`` checks that every public name and every test file is listed.
"""
from __future__ import annotations

import ast
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]
PACKAGE = REPO / "hyde_bsdf"
OUT = REPO / "docs" / "api.md"

HEADER = """# Reference: the Python API

Every public name of `hyde_bsdf` (each module's `__all__`), its signature and the first line of its
docstring; `help(name)` shows the whole docstring (or, for a module, `python -m pydoc hyde_bsdf.inverse`). The
guides: [plugin `hyde`](plugin.md) (the plugin's parameters), [NumPy evaluator](evaluator.md),
[command line](cli.md), and the tutorials in [the index](index.md).

This page is generated from the source by `docs/tools/make_api.py`; `tests/test_docs.py` fails
when it is out of date.
"""


def _module_name(path: Path) -> str:
    rel = path.relative_to(REPO).with_suffix("")
    parts = list(rel.parts)
    if parts[-1] == "__init__":
        parts = parts[:-1]
    return ".".join(parts)


def _literal_all(tree: ast.Module):
    for node in tree.body:
        if isinstance(node, ast.Assign) and any(isinstance(t, ast.Name) and t.id == "__all__"
                                                for t in node.targets):
            try:
                value = ast.literal_eval(node.value)
            except ValueError:
                return None
            return [str(v) for v in value]
    return None


def _md(text: str) -> str:
    """reST inline markup to Markdown: ``x`` -> `x`, :func:`x` -> `x`."""
    import re

    text = re.sub(r":(?:func|class|mod|data|meth|attr):`~?([^`]+)`", r"`\1`", text)
    return text.replace("``", "`")


def _first_line(doc: str | None) -> str:
    if not doc:
        return ""
    para = doc.strip().split("\n\n")[0]
    return _md(" ".join(line.strip() for line in para.splitlines()))


def _source_tree(module: str):
    """The parsed source of a module of this package (None outside it)."""
    if not module or not module.startswith("hyde_bsdf"):
        return None, None
    base = REPO.joinpath(*module.split("."))
    for path in (base.with_suffix(".py"), base / "__init__.py"):
        if path.exists():
            return ast.parse(path.read_text(encoding="utf-8")), path.read_text(encoding="utf-8").splitlines()
    return None, None


def _signature(node) -> str:
    text = ast.unparse(node.args)
    return f"({text})"


def _describe(tree: ast.Module, name: str, lines=None, depth=0) -> tuple[str, str]:
    """(kind + signature, first docstring line) of ``name`` defined in ``tree``."""
    for node in tree.body:
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)) and node.name == name:
            return f"`{name}{_signature(node)}`", _first_line(ast.get_docstring(node))
        if isinstance(node, ast.ClassDef) and node.name == name:
            init = next((n for n in node.body if isinstance(n, ast.FunctionDef) and n.name == "__init__"), None)
            sig = _signature(init).replace("(self, ", "(").replace("(self)", "()") if init else ""
            return f"class `{name}{sig}`", _first_line(ast.get_docstring(node))
    # a constant: its value, and the "#: comment" lines just above its assignment
    for node in tree.body:
        targets = (node.targets if isinstance(node, ast.Assign) else
                   [node.target] if isinstance(node, ast.AnnAssign) else [])
        if any(isinstance(t, ast.Name) and t.id == name for t in targets):
            value = ast.unparse(node.value) if node.value is not None else ""
            if len(value) > 60:
                value = value[:57] + "..."
            comment = []
            if lines:
                i = node.lineno - 2
                while i >= 0 and lines[i].lstrip().startswith("#:"):
                    comment.insert(0, lines[i].lstrip()[2:].strip())
                    i -= 1
            return f"`{name} = {value}`", _md(" ".join(comment))
    for node in tree.body:   # a lazy export: a {name: "hyde_bsdf.module"} table read by __getattr__
        if isinstance(node, ast.Assign) and isinstance(node.value, ast.Dict):
            try:
                table = ast.literal_eval(node.value)
            except ValueError:
                continue
            target = table.get(name)
            if isinstance(target, str) and target.startswith("hyde_bsdf") and depth < 3:
                sub, sub_lines = _source_tree(target)
                if sub is not None:
                    head, doc = _describe(sub, name, sub_lines, depth + 1)
                    return head, (doc + " " if doc else "") + f"(from `{target}`)"
    for node in tree.body:   # re-exported: describe it where it is defined
        if isinstance(node, ast.ImportFrom) and any((a.asname or a.name) == name for a in node.names):
            sub, sub_lines = _source_tree(node.module)
            if sub is not None and depth < 3:
                head, doc = _describe(sub, name, sub_lines, depth + 1)
                return head, (doc + " " if doc else "") + f"(from `{node.module}`)"
            return f"`{name}`", f"from `{node.module}`"
    return f"`{name}`", ""


#: module order on the page: what a user calls first, then the layers below it
ORDER = ("hyde_bsdf", "hyde_bsdf.render", "hyde_bsdf.inverse", "hyde_bsdf.fit", "hyde_bsdf.mom", "hyde_bsdf.mitsuba",
         "hyde_bsdf.model", "hyde_bsdf.app.report", "hyde_bsdf.io.atomic", "hyde_bsdf.app.cli")


def _order(mod: str):
    best = max((p for p in ORDER if mod == p or mod.startswith(p + ".")), key=len, default="")
    return (ORDER.index(best) if best else len(ORDER), mod.count(".") if best != "hyde_bsdf" else 0, mod)


def modules() -> list[tuple[str, ast.Module, str, list]]:
    """(module name, tree, source, __all__) of every package module with a literal ``__all__``
    (the validation scripts, which run as programs, are no API)."""
    found = []
    for path in PACKAGE.rglob("*.py"):
        parts = path.relative_to(PACKAGE).parts
        if parts[0] == "validation" or any(p.startswith("_") and p != "__init__.py" for p in parts):
            continue
        source = path.read_text(encoding="utf-8")
        tree = ast.parse(source)
        names = _literal_all(tree)
        if names:
            found.append((_module_name(path), tree, source, names))
    return sorted(found, key=lambda m: _order(m[0]))


def public_names() -> dict:
    """{module: [public names]}: what docs/api.md must list."""
    return {mod: names for mod, _, _, names in modules()}


def render() -> str:
    out = [HEADER]
    mods = modules()
    out.append("Modules: " + " · ".join(f"[`{m}`](#{m.replace('.', '')})" for m, *_ in mods) + "\n")
    for mod, tree, source, names in mods:
        out.append(f"## `{mod}`\n")
        summary = _first_line(ast.get_docstring(tree))
        if summary:
            out.append(summary + "\n")
        out.append("| name | what |\n|---|---|")
        for name in names:
            head, doc = _describe(tree, name, source.splitlines())
            doc = doc.replace("|", "\\|")
            out.append(f"| {head.replace('|', chr(92) + '|')} | {doc} |")
        out.append("")
    return "\n".join(out).rstrip() + "\n"


VALIDATION = REPO / "docs" / "validation.md"
BEGIN_TESTS, END_TESTS = "<!-- BEGIN tests -->", "<!-- END tests -->"


def render_tests() -> str:
    """The table of tests/test_*.py: file, first paragraph of its docstring."""
    rows = ["| file | what it checks |", "|---|---|"]
    for path in sorted((REPO / "tests").glob("test_*.py")):
        doc = _first_line(ast.get_docstring(ast.parse(path.read_text(encoding="utf-8"))))
        rows.append(f"| `tests/{path.name}` | {doc.replace('|', chr(92) + '|')} |")
    return "\n".join(rows)


def updated_validation() -> str:
    text = VALIDATION.read_text(encoding="utf-8")
    start, end = text.index(BEGIN_TESTS) + len(BEGIN_TESTS), text.index(END_TESTS)
    return text[:start] + "\n" + render_tests() + "\n" + text[end:]


def main(argv=None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    outputs = {OUT: render(), VALIDATION: updated_validation()}
    if "--check" in argv:
        stale = [p for p, text in outputs.items() if (p.read_text(encoding="utf-8") if p.exists() else "") != text]
        for p in stale:
            print(f"{p.relative_to(REPO)} is out of date: run .venv/bin/python docs/tools/make_api.py",
                  file=sys.stderr)
        return 1 if stale else 0
    for p, text in outputs.items():
        p.write_text(text, encoding="utf-8")
        print(f"wrote {p.relative_to(REPO)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
