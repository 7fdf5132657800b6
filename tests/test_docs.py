"""The documentation cannot rot: README.md and every page under docs/ are checked here.

* Every fenced ```python block runs.  The blocks of one page run in order in one subprocess
  (a shared namespace, like a notebook), with the current directory a scratch folder that
  links ``hyde_bsdf/`` (its scenes and validation scripts) and ``benchmarks/`` of this checkout, and with
  ``HYDE_DOCS_FAST=1`` set: a snippet may read it to pick smaller sizes.  A block that is
  deliberately not runnable is fenced as ```python no-run; there are at most MAX_NO_RUN.
* A block fenced as ```xml file=NAME is written to NAME in that folder before the page's
  Python blocks run ("save this as NAME"); every ```xml block (unless ``no-run``) is then
  loaded with ``mi.load_string`` in ``llvm_ad_spectral_polarized`` after ``register()``.
* Every relative link (and image) points at an existing file, and an ``#anchor`` into a
  Markdown page at one of its headings.
* Every repository path the text names (``hyde_bsdf/data/scenes/demo.xml``, ``hyde_bsdf/validation/fig6_mom.py``, ...)
  exists, and every dotted name ``hyde_bsdf.x.y`` resolves to a module or a name defined in one.
* Every command line shown (in ```sh blocks and in inline code): ``hyde-bsdf SUB`` is a
  sub-command and each of its ``--flags`` appears in ``hyde-bsdf SUB --help`` (which is run);
  ``python SCRIPT`` names an existing script whose source defines each flag; ``pytest FILE
  -k WORD`` names an existing test file containing WORD; ``./run.sh X`` is one of run.sh's
  commands.
* The front page stays a front page (<= 200 lines, picture < 300 kB), and the plugin
  reference lists every parameter the plugin accepts and the CLI page every sub-command.

Budget: <= 90 s on 2 cores with a warm Dr.Jit kernel cache (all pages share one variant;
measured 42 s wall, 41 s CPU, at a load average of 1.4 on the shared 2-core machine).
"""
from __future__ import annotations

import ast
import functools
import importlib.util
import json
import os
import re
import shlex
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

import pytest
from conftest import scaled

REPO = Path(__file__).resolve().parents[1]
PAGES = [REPO / "README.md", *sorted((REPO / "docs").rglob("*.md"))]
MAX_NO_RUN = 6
PAGE_TIMEOUT_S = 240
VARIANT = "llvm_ad_spectral_polarized"


@dataclass
class Block:
    page: Path
    line: int          # 1-based line of the first code line
    lang: str
    flags: dict        # e.g. {"no-run": True, "file": "my_scene.xml"}
    code: str


def _rel(page: Path) -> str:
    return str(page.relative_to(REPO))


@functools.lru_cache(maxsize=None)
def blocks(page: Path) -> tuple[Block, ...]:
    """The fenced code blocks of a Markdown page (``` fences, info string = lang + flags)."""
    out, lines = [], page.read_text(encoding="utf-8").splitlines()
    i = 0
    while i < len(lines):
        m = re.match(r"^(\s*)```(.*)$", lines[i])
        if not m:
            i += 1
            continue
        info = m.group(2).split()
        lang = info[0] if info else ""
        flags = {}
        for word in info[1:]:
            key, _, value = word.partition("=")
            flags[key] = value or True
        j = i + 1
        while j < len(lines) and not re.match(r"^\s*```\s*$", lines[j]):
            j += 1
        assert j < len(lines), f"{_rel(page)}:{i + 1}: unclosed code fence"
        indent = len(m.group(1))
        code = "\n".join(x[indent:] if x[:indent].isspace() else x for x in lines[i + 1:j])
        out.append(Block(page, i + 2, lang, flags, code + "\n"))
        i = j + 1
    return tuple(out)


def prose(page: Path) -> str:
    """The page's text with its code blocks blanked (line numbers kept)."""
    text = page.read_text(encoding="utf-8")
    return re.sub(r"^\s*```.*?^\s*```\s*$", lambda m: "\n" * m.group(0).count("\n"), text,
                  flags=re.M | re.S)


def test_pages_exist():
    names = {_rel(p) for p in PAGES}
    for required in ("docs/index.md", "docs/architecture.md", "docs/plugin.md", "docs/conventions.md", "docs/validation.md",
                     "docs/troubleshooting.md"):
        assert required in names


def test_front_page_is_short_with_a_small_picture():
    lines = (REPO / "README.md").read_text(encoding="utf-8").splitlines()
    assert len(lines) <= 200, f"README.md has {len(lines)} lines; the front page keeps <= 200"
    pictures = re.findall(r"!\[[^\]]*\]\(([^)]+)\)", "\n".join(lines))
    assert pictures, "README.md shows the demo picture"
    for pic in pictures:
        size = (REPO / pic).stat().st_size
        assert size < 300_000, f"{pic} is {size} bytes; keep pictures < 300 kB"


def test_no_run_blocks_are_rare_and_every_python_block_is_marked():
    no_run = [b for p in PAGES for b in blocks(p) if b.lang == "python" and b.flags.get("no-run")]
    assert len(no_run) <= MAX_NO_RUN, [f"{_rel(b.page)}:{b.line}" for b in no_run]
    for p in PAGES:
        for b in blocks(p):
            assert b.lang != "py", f"{_rel(p)}:{b.line}: fence Python as ```python"
            unknown = set(b.flags) - {"no-run", "file"}
            assert not unknown, f"{_rel(p)}:{b.line}: unknown fence flags {unknown}"


# ----------------------------------------------------------------------------------------------
# Running the code

_DRIVER = r'''
import json, os, sys, traceback
spec = json.load(open(sys.argv[1]))
for f in spec["files"]:
    with open(f["name"], "w") as fh:
        fh.write(f["code"])
ns = {"__name__": "__main__"}
for b in spec["python"]:
    code = compile("\n" * (b["line"] - 1) + b["code"], b["page"], "exec")
    exec(code, ns)
    sys.stdout.flush()
if spec["xml"]:
    import mitsuba as mi, hyde_bsdf
    from hyde_bsdf.mitsuba.variants import set_variant
    set_variant(spec["variant"])
    hyde_bsdf.register()
    for b in spec["xml"]:
        text = b["code"]
        if "version=" not in text.split(">", 1)[0]:
            text = text.replace(">", ' version="3.0.0">', 1) if not text.lstrip().startswith("<?") else text
        try:
            mi.load_string(text)
        except Exception as exc:
            sys.exit(f"{b['page']}:{b['line']}: the XML block does not load: {exc}")
print("DOCS-PAGE-OK")
'''


def _runnable_pages():
    pages = []
    for p in PAGES:
        bl = blocks(p)
        if any(b.lang in ("python", "xml") and not b.flags.get("no-run") for b in bl):
            pages.append(p)
    return pages


@pytest.mark.parametrize("page", _runnable_pages(), ids=_rel)
def test_code_blocks_run(page, tmp_path):
    """Each page's Python blocks run in order in one process; its XML blocks load."""
    for name in ("hyde_bsdf", "benchmarks"):
        (tmp_path / name).symlink_to(REPO / name)
    bl = [b for b in blocks(page) if not b.flags.get("no-run")]
    spec = {
        "variant": VARIANT,
        "files": [{"name": b.flags["file"], "code": b.code} for b in bl if b.flags.get("file")],
        "python": [{"page": str(page), "line": b.line, "code": b.code} for b in bl if b.lang == "python"],
        "xml": [{"page": str(page), "line": b.line, "code": b.code} for b in bl if b.lang == "xml"],
    }
    (tmp_path / "_spec.json").write_text(json.dumps(spec))
    (tmp_path / "_driver.py").write_text(_DRIVER)
    env = dict(os.environ, HYDE_DOCS_FAST="1", MPLBACKEND="Agg",
               PYTHONPATH=str(REPO) + os.pathsep + os.environ.get("PYTHONPATH", ""))
    proc = subprocess.run([sys.executable, "_driver.py", "_spec.json"], cwd=tmp_path, env=env,
                          capture_output=True, text=True, timeout=scaled(PAGE_TIMEOUT_S))
    assert proc.returncode == 0 and "DOCS-PAGE-OK" in proc.stdout, (
        f"{_rel(page)}: a code block failed\n--- stdout\n{proc.stdout[-3000:]}\n"
        f"--- stderr\n{proc.stderr[-6000:]}")


# ----------------------------------------------------------------------------------------------
# Links and file names

def _slug(heading: str) -> str:
    """GitHub's anchor for a heading."""
    text = re.sub(r"[`*]|<[^>]+>", "", heading.strip().lower())
    text = re.sub(r"\[([^\]]*)\]\([^)]*\)", r"\1", text)
    text = re.sub(r"[^\w\- ]", "", text)
    return text.replace(" ", "-")


def _anchors(page: Path) -> set[str]:
    return {_slug(m.group(1)) for m in re.finditer(r"^#{1,6}\s+(.*)$", prose(page), flags=re.M)}


@pytest.mark.parametrize("page", PAGES, ids=_rel)
def test_relative_links_resolve(page):
    bad = []
    for target in re.findall(r"\]\(([^)\s]+)\)", prose(page)):
        if re.match(r"^[a-z]+:", target):
            continue
        path, _, anchor = target.partition("#")
        dest = (page.parent / path).resolve() if path else page
        if not dest.exists():
            bad.append(f"{target} (no such file)")
        elif anchor and dest.suffix == ".md" and anchor not in _anchors(dest):
            bad.append(f"{target} (no heading #{anchor} in {dest.name})")
    assert not bad, f"{_rel(page)}: broken links: {bad}"


_PATH = re.compile(r"(?<![\w./~-])((?:hyde_bsdf|scenes|validation|benchmarks|tests|docs|\.ci)/"
                   r"[\w.{},*/-]*[\w}*/]|README\.md|run\.sh|pyproject\.toml)")


def _expand(path: str) -> list[str]:
    m = re.search(r"\{([^{}]*)\}", path)
    if not m:
        return [path]
    return [x for alt in m.group(1).split(",") for x in _expand(path[:m.start()] + alt + path[m.end():])]


@pytest.mark.parametrize("page", PAGES, ids=_rel)
def test_named_repository_files_exist(page):
    text = page.read_text(encoding="utf-8")
    missing = []
    for raw in set(_PATH.findall(text)):
        for path in _expand(raw):
            if "*" in path:
                if not list(REPO.glob(path)):
                    missing.append(path)
            elif not (REPO / path).exists():
                missing.append(path)
    assert not missing, f"{_rel(page)} names files that do not exist: {sorted(missing)}"


def _defines(module_file: Path, name: str) -> bool:
    """``name`` is defined, imported or listed in ``__all__`` (lazy exports) by the module."""
    tree = ast.parse(module_file.read_text(encoding="utf-8"))
    for node in tree.body:
        if isinstance(node, ast.Assign) and any(isinstance(t, ast.Name) and t.id == "__all__"
                                                for t in node.targets):
            try:
                if name in ast.literal_eval(node.value):
                    return True
            except ValueError:
                pass
    for node in ast.walk(tree):
        if isinstance(node, (ast.FunctionDef, ast.ClassDef, ast.AsyncFunctionDef)) and node.name == name:
            return True
        if isinstance(node, (ast.Assign, ast.AnnAssign)):
            targets = node.targets if isinstance(node, ast.Assign) else [node.target]
            for t in targets:
                for n in ast.walk(t):
                    if isinstance(n, ast.Name) and n.id == name:
                        return True
        if isinstance(node, ast.ImportFrom):
            if any((a.asname or a.name) == name for a in node.names):
                return True
    return False


def _resolves(dotted: str) -> bool:
    parts = dotted.split(".")
    for cut in range(len(parts), 0, -1):
        mod = ".".join(parts[:cut])
        try:
            spec = importlib.util.find_spec(mod)
        except (ImportError, ValueError):
            spec = None
        if spec is None or not spec.origin:
            continue
        rest = parts[cut:]
        if not rest:
            return True
        if len(rest) == 1 or len(rest) == 2:   # a name in the module (or an attribute of a class)
            origin = Path(spec.origin)
            if _defines(origin, rest[0]):
                return True
            # re-exported by a package __init__ with `import *`: look in its submodules
            if origin.name == "__init__.py":
                return any(_defines(f, rest[0]) for f in origin.parent.glob("*.py"))
        return False
    return False


@pytest.mark.parametrize("page", PAGES, ids=_rel)
def test_named_python_objects_exist(page):
    text = page.read_text(encoding="utf-8")
    names = set(re.findall(r"(?<![\w/.])(hyde_bsdf(?:\.[A-Za-z_]\w*)+)", text))
    missing = sorted(n for n in names if not _resolves(n))
    assert not missing, f"{_rel(page)} names Python objects that do not exist: {missing}"


# ----------------------------------------------------------------------------------------------
# Command lines

def _cli_commands() -> dict:
    sys.path.insert(0, str(REPO))
    try:
        spec = importlib.util.spec_from_file_location("_hyde_cli", REPO / "hyde_bsdf" / "app" / "cli.py")
        mod = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(mod)
        return dict(mod.COMMANDS)
    finally:
        sys.path.pop(0)


@functools.lru_cache(maxsize=None)
def _cli_help(sub: str) -> str:
    proc = subprocess.run([sys.executable, "-m", "hyde_bsdf.app.cli", sub, "--help"], cwd=REPO,
                          capture_output=True, text=True, timeout=scaled(120),
                          env=dict(os.environ, PYTHONPATH=str(REPO)))
    assert proc.returncode == 0, f"hyde-bsdf {sub} --help failed: {proc.stderr[-2000:]}"
    return proc.stdout


def _command_lines(page: Path):
    """(line number, command text) of every shell command the page shows."""
    out = []
    for b in blocks(page):
        if b.lang in ("sh", "bash", "console", "shell") and not b.flags.get("no-run"):
            for k, line in enumerate(b.code.splitlines()):
                line = re.sub(r"(^|\s)#.*$", "", line).strip()
                if line:
                    out.append((b.line + k, line))
    for n, line in enumerate(prose(page).splitlines(), 1):
        for m in re.finditer(r"`((?:\./run\.sh|(?:\.venv/bin/)?hyde-bsdf|(?:\.venv/bin/)?python|pytest)"
                             r"(?: [^`]*)?)`", line):
            out.append((n, m.group(1)))
    return out


def _flags(tokens):
    return [t.split("=", 1)[0] for t in tokens if t.startswith("-") and t not in ("-", "--")]


_PLACEHOLDER = re.compile(r"^(?:[A-Z][A-Z_]+:?|.*<[^>]*>.*)$")   # COMMAND, CMD, hyde_bsdf/validation/<name>.py


def _check_command(cmd: str, commands: dict) -> list[str]:
    """Problems with one shown command line (placeholders such as COMMAND or <name> are skipped)."""
    problems = []
    if re.search(r": error\b", cmd):       # an error message quoted in the text, not a command
        return problems
    for part in re.split(r"\s*(?:&&|\|\||;|\|)\s*", cmd):
        try:
            tok = shlex.split(part)
        except ValueError:
            tok = part.split()
        while tok and "=" in tok[0] and not tok[0].startswith("-"):   # VAR=value prefix
            tok = tok[1:]
        if not tok or any(_PLACEHOLDER.match(x) for x in tok[:2]):
            continue
        prog = os.path.basename(tok[0])
        if tok[0] in ("./run.sh", "run.sh"):
            if len(tok) > 1 and tok[1] not in ("demo", "test", "wheel"):
                problems.append(f"{part}: run.sh has only 'demo', 'test' and 'wheel'")
            elif len(tok) > 1 and tok[1] == "test":
                problems += _check_pytest_args(tok[2:], part)
        elif prog == "hyde-bsdf":
            if len(tok) < 2 or tok[1] in ("-h", "--help", "--version", "-V"):
                continue
            sub = tok[1]
            if sub not in commands:
                problems.append(f"{part}: no sub-command {sub!r} (have {', '.join(commands)})")
                continue
            help_text = _cli_help(sub)
            for flag in _flags(tok[2:]):
                if not re.search(r"(?<![\w-])" + re.escape(flag) + r"(?![\w-])", help_text):
                    problems.append(f"{part}: 'hyde-bsdf {sub}' has no option {flag}")
        elif prog in ("python", "python3"):
            args = tok[1:]
            if args[:2] == ["-m", "pytest"]:
                problems += _check_pytest_args(args[2:], part)
            elif args and args[0] == "-m":
                if len(args) < 2 or importlib.util.find_spec(args[1].split(".")[0]) is None:
                    problems.append(f"{part}: no module {args[1:2]}")
            elif args and args[0].endswith(".py"):
                script = REPO / args[0]
                if not script.exists():
                    problems.append(f"{part}: no script {args[0]}")
                    continue
                source = script.read_text(encoding="utf-8")
                common = REPO / "hyde_bsdf" / "validation" / "_common.py"
                if script.parent.name == "validation" and common.exists():
                    source += common.read_text(encoding="utf-8")
                for flag in _flags(args[1:]):
                    if f'"{flag}"' not in source and f"'{flag}'" not in source:
                        problems.append(f"{part}: {args[0]} defines no option {flag}")
        elif prog == "pytest":
            problems += _check_pytest_args(tok[1:], part)
    return problems


def _check_pytest_args(args, part):
    problems, files = [], []
    it = iter(range(len(args)))
    for i in it:
        a = args[i]
        if a == "-k" and i + 1 < len(args):
            words = re.findall(r"\w+", args[i + 1])
            words = [w for w in words if w not in ("and", "or", "not")]
            text = "".join(f.read_text(encoding="utf-8") for f in files) if files else ""
            for w in words:
                if files and w not in text:
                    problems.append(f"{part}: -k {w!r} matches nothing in {[f.name for f in files]}")
            next(it, None)
        elif not a.startswith("-"):
            target = REPO / a.split("::")[0]
            if "*" in a:
                if not list(REPO.glob(a)):
                    problems.append(f"{part}: no test files match {a}")
                files += list(REPO.glob(a))
            elif not target.exists():
                problems.append(f"{part}: no test file {a}")
            else:
                files.append(target)
    return problems


@pytest.mark.parametrize("page", PAGES, ids=_rel)
def test_commands_and_flags_exist(page):
    commands = _cli_commands()
    problems = []
    for line, cmd in _command_lines(page):
        problems += [f"line {line}: {p}" for p in _check_command(cmd, commands)]
    assert not problems, f"{_rel(page)}:\n" + "\n".join(problems)


def test_cli_page_lists_every_sub_command():
    text = (REPO / "docs" / "cli.md").read_text(encoding="utf-8")
    for sub in _cli_commands():
        assert f"hyde-bsdf {sub}" in text, f"docs/cli.md does not document 'hyde-bsdf {sub}'"


def test_plugin_reference_lists_every_parameter():
    """The parameters the plugin accepts (its _PARAMS tuple) each have a row in docs/plugin.md."""
    tree = ast.parse((REPO / "hyde_bsdf" / "mitsuba" / "plugin.py").read_text(encoding="utf-8"))
    params = None
    for node in ast.walk(tree):
        if isinstance(node, ast.Assign) and any(isinstance(t, ast.Name) and t.id == "_PARAMS"
                                                for t in node.targets):
            params = ast.literal_eval(node.value)
    assert params, "hyde_bsdf/mitsuba/plugin.py defines _PARAMS"
    rows = [line for line in (REPO / "docs" / "plugin.md").read_text(encoding="utf-8").splitlines()
            if line.startswith("|")]
    for name in params:
        assert any(f"`{name}`" in row.split("|")[1] for row in rows if row.count("|") > 2), (
            f"docs/plugin.md has no parameter row for {name!r}")


def test_api_page_lists_every_public_name():
    """docs/api.md (generated by docs/tools/make_api.py) lists every name of every module's
    ``__all__`` under that module's heading: a new public function cannot go undocumented."""
    spec = importlib.util.spec_from_file_location("_make_api", REPO / "docs" / "tools" / "make_api.py")
    make_api = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(make_api)
    text = (REPO / "docs" / "api.md").read_text(encoding="utf-8")
    sections = dict(re.findall(r"^## `([\w.]+)`\n(.*?)(?=^## |\Z)", text, flags=re.M | re.S))
    missing = []
    for module, names in make_api.public_names().items():
        body = sections.get(module)
        if body is None:
            missing.append(f"section {module}")
            continue
        listed = set(re.findall(r"^\| (?:class )?`(\w+)", body, flags=re.M))
        missing += [f"{module}.{n}" for n in names if n not in listed]
    assert not missing, ("docs/api.md is missing " + ", ".join(missing)
                         + "; run .venv/bin/python docs/tools/make_api.py")


def test_validation_page_lists_every_test_file():
    """The table of test files in docs/validation.md (generated by docs/tools/make_api.py) is complete."""
    text = (REPO / "docs" / "validation.md").read_text(encoding="utf-8")
    missing = [f.name for f in sorted((REPO / "tests").glob("test_*.py")) if f"`tests/{f.name}`" not in text]
    assert not missing, (f"docs/validation.md does not list {missing}; "
                         "run .venv/bin/python docs/tools/make_api.py")


@pytest.mark.parametrize("page", PAGES, ids=_rel)
def test_tables_have_one_cell_count(page):
    """Every row of a Markdown table has as many cells as its header (a stray | breaks a table)."""
    bad, count = [], None
    for n, line in enumerate(prose(page).splitlines(), 1):
        if line.startswith("|"):
            cells = len(re.findall(r"(?<!\\)\|", line))
            if count is None:
                count = cells
            elif cells != count:
                bad.append(f"line {n}: {cells - 1} cells, the header has {count - 1}")
        else:
            count = None
    assert not bad, f"{_rel(page)}: " + "; ".join(bad)


def test_report_tutorial_lists_every_validation_script():
    """docs/tutorials/report.md's table of sections names every script of the report's SECTIONS."""
    tree = ast.parse((REPO / "hyde_bsdf" / "app" / "report" / "build.py").read_text(encoding="utf-8"))
    sections = None
    for node in ast.walk(tree):
        if isinstance(node, ast.Assign) and any(isinstance(t, ast.Name) and t.id == "SECTIONS" for t in node.targets):
            sections = ast.literal_eval(node.value)
    assert sections, "hyde_bsdf/app/report/build.py defines SECTIONS"
    text = (REPO / "docs" / "tutorials" / "report.md").read_text(encoding="utf-8")
    missing = [s for _, scripts in sections for s in scripts if f"`{s}`" not in text]
    assert not missing, f"docs/tutorials/report.md does not list the report's scripts {missing}"


#: what silences a warning in Python code (simplefilter/filterwarnings "ignore", -W ignore, a
#: warnings.catch_warnings that records without re-issuing is allowed: the page then prints or asserts them)
SILENCERS = re.compile(r"""(simplefilter|filterwarnings)\(\s*["']ignore["']|-W\s*["']?ignore|PYTHONWARNINGS\s*=\s*["']?ignore""")


@pytest.mark.parametrize("page", PAGES, ids=_rel)
def test_no_page_silences_warnings(page):
    """A docs page must not hide a warning: the package's warnings (a parameter the data do not
    determine, a fit that has not converged, a bilinear map) are the answer's honesty, and a page that
    ignores them teaches users to do the same (issue 22: the capture tutorial hid a 267 % standard
    error this way).  Recording them (``catch_warnings(record=True)``) and printing them is fine."""
    found = [f"line {i + 1}: {line.strip()}" for i, line in enumerate(page.read_text(encoding="utf-8").splitlines())
             if SILENCERS.search(line)]
    assert not found, f"{_rel(page)} silences warnings: " + "; ".join(found)
