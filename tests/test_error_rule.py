"""One error rule: the library reports a user's mistake with the package's own exceptions.

``hyde_bsdf.errors`` defines them (UsageError, a ValueError; UsageTypeError, a TypeError;
InputFileError; OutputError; RejectedResult), and the command line turns each into one line and an
exit status in one place (``hyde_bsdf.app.cli``).  A plain ``raise ValueError(...)`` or
``raise TypeError(...)`` in the library escapes that rule: the command line shows it as a crash
with a traceback.  This test reads the source (every ``raise`` statement, multi-line ones too,
parsed with ``ast``) and fails on a plain one outside the allow-list below; an internal invariant
(a bug, not a user's mistake) is an ``assert`` or a commented ``RuntimeError`` instead.
"""
from __future__ import annotations

import ast
from pathlib import Path

import pytest
from conftest import library_modules

PACKAGE = Path(__file__).resolve().parent.parent / "hyde_bsdf"

#: the built-in exceptions a user's mistake must not be raised as
PLAIN = {"ValueError", "TypeError"}

#: files (relative to hyde_bsdf/) that may still raise a plain ValueError/TypeError, each with why
#: (none: every library module raises the package's exceptions)
ALLOWED: dict[str, str] = {}


def _plain_raises(path: Path, root: Path = PACKAGE) -> list[str]:
    """'file:line: raise NAME' for every ``raise ValueError``/``raise TypeError`` (called or bare)
    in ``path`` (named relative to ``root``)."""
    tree = ast.parse(path.read_text(encoding="utf-8"), str(path))
    out = []
    for node in ast.walk(tree):
        if not isinstance(node, ast.Raise) or node.exc is None:
            continue
        exc = node.exc.func if isinstance(node.exc, ast.Call) else node.exc
        if isinstance(exc, ast.Name) and exc.id in PLAIN:
            out.append(f"{path.relative_to(root).as_posix()}:{node.lineno}: raise {exc.id}")
    return out


def _library_files():
    return library_modules(PACKAGE)


def test_no_plain_value_or_type_error_outside_the_allow_list():
    found = [hit for path in _library_files()
             if path.relative_to(PACKAGE).as_posix() not in ALLOWED for hit in _plain_raises(path)]
    assert not found, ("a user's mistake raises hyde_bsdf.errors.UsageError (a ValueError) or UsageTypeError "
                       "(a TypeError); an internal invariant is an assert or a commented RuntimeError:\n"
                       + "\n".join(found))


def test_the_allow_list_has_no_stale_entry():
    """Every entry names an existing file that still raises a plain one: an entry for a renamed or
    converted file would silently allow the next plain raise there."""
    stale = [name for name in ALLOWED if not (PACKAGE / name).is_file() or not _plain_raises(PACKAGE / name)]
    assert not stale, f"remove from ALLOWED (no such file, or no plain raise left in it): {stale}"


@pytest.mark.parametrize("source, hits", [
    ("raise ValueError('x')", 1),
    ("raise TypeError(\n    'multi'\n    'line')", 1),
    ("raise ValueError", 1),
    ("raise UsageError('x')", 0),
    ("try:\n    pass\nexcept ValueError:\n    raise", 0),
    ("raise RuntimeError('invariant')  # a bug, not the user's mistake", 0),
])
def test_the_scan_sees_every_form(tmp_path, source, hits):
    """The scan itself: called, bare and multi-line plain raises count; the package's own
    exceptions, re-raises and RuntimeError do not."""
    (tmp_path / "m.py").write_text(source + "\n")
    assert len(_plain_raises(tmp_path / "m.py", tmp_path)) == hits
