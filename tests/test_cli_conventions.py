"""Conventions every ``hyde-bsdf`` sub-command follows (issue 24, item 6).

``--version`` and ``hyde_bsdf.__version__`` come from the package metadata; every option of every
sub-command has help text; options may stand before or after the data file; ``-q`` leaves stderr
empty on a run that succeeds (progress and summary lines only: no warning or error is hidden);
a message that echoes a 100 KB value stays one short line.  All in-process and fast (no render).
"""
from __future__ import annotations

import argparse
import importlib
import inspect

import numpy as np
import pytest
from conftest import library_modules

import hyde_bsdf
from hyde_bsdf.app.cli import COMMANDS, main
from hyde_bsdf.errors import MESSAGE_VALUE_LIMIT, SHORTEN_LIMIT, shorten, shorten_values


def _parsers():
    """(command, parser) for every argument parser of every sub-command module."""
    for command, (module_name, _) in COMMANDS.items():
        module = importlib.import_module(module_name)
        for name, fn in inspect.getmembers(module, inspect.isfunction):
            if name.endswith("parser") and fn.__module__ == module.__name__:
                parser = fn()
                assert isinstance(parser, argparse.ArgumentParser), (command, name)
                yield command, parser


def test_version_is_the_package_metadata(capsys):
    from importlib import metadata

    assert main(["--version"]) == 0
    assert capsys.readouterr().out.strip() == f"hyde-bsdf {hyde_bsdf.__version__}"
    try:
        assert hyde_bsdf.__version__ == metadata.version("hyde-bsdf")
    except metadata.PackageNotFoundError:       # a checkout never installed: pyproject.toml's
        assert hyde_bsdf.__version__ != "unknown"


def test_every_option_of_every_command_has_help_text():
    seen = set()
    for command, parser in _parsers():
        seen.add(command)
        bare = [a.option_strings or a.dest for a in parser._actions
                if not isinstance(a, argparse._HelpAction) and not (a.help or "").strip()]
        assert not bare, f"hyde-bsdf {command}: options without help text: {bare}"
        assert any("-q" in a.option_strings for a in parser._actions), f"hyde-bsdf {command} has no -q"
    assert seen == set(COMMANDS)


def _tiny_csv(tmp_path):
    from hyde_bsdf.fit import synthetic_measurements
    from hyde_bsdf.io.measurements import write_measurements

    a = np.radians([20.0, 40.0, 60.0, 75.0])
    meas = synthetic_measurements(a, a, np.pi, ("M01", "M22", "M23"), rms_slope=0.43, n=1.2, k=10.0,
                                  noise=0.01, n_samples=64, rng=5)
    return write_measurements(tmp_path / "tiny.csv", meas)


def test_options_before_the_file_reach_the_reader_of_that_file(tmp_path, capsys):
    """``fit --fit n,k t.pbsdf``: the option's value is not taken for the file (it used to be,
    and the table went to the CSV reader)."""
    table = tmp_path / "t.pbsdf"
    table.write_bytes(b"not a table")
    for argv in (["fit", "--fit", "n,k", str(table)], ["fit", str(table), "--fit", "n,k"]):
        assert main(argv) == 2
        err = capsys.readouterr().err
        assert "pBSDF file" in err and "not a Mitsuba tensor file" in err, err
    csv = _tiny_csv(tmp_path)
    for argv in (["fit", "--fit", "n,k", "--rms-slope", "0.43", str(csv), "-q"],
                 ["fit", str(csv), "--fit", "n,k", "--rms-slope", "0.43", "-q"]):
        assert main(argv) == 0
        out, err = capsys.readouterr()
        assert "n         = 1.2" in out and err == "", err


def test_quiet_leaves_stderr_empty_but_keeps_warnings(tmp_path, capsys):
    """-q: no progress or summary line; a warning the fit raises still reaches stderr, one line."""
    csv = _tiny_csv(tmp_path)
    assert main(["fit", str(csv), "--fit", "n,k", "--rms-slope", "0.43", "-q"]) == 0
    assert capsys.readouterr().err == ""
    from hyde_bsdf.progress import stderr_lines

    report = stderr_lines()
    import hyde_bsdf.progress as progress

    old = progress.set_quiet(True)
    try:
        report("hidden")
    finally:
        progress.set_quiet(old)
    report("shown")
    assert capsys.readouterr().err == "[hyde-bsdf] shown\n"


def test_long_values_are_cut_in_messages(tmp_path, capsys):
    """A 100 KB material name is echoed as a short line (it used to be echoed whole)."""
    name = "Au" * 50_000
    assert main(["export", str(tmp_path / "t.pbsdf"), "--rms-slope", "0.3", "--material", name]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and len(err) < 3 * MESSAGE_VALUE_LIMIT + 200, len(err)
    assert "characters]" in err
    short = shorten("x" * 10_000)
    assert len(short) < SHORTEN_LIMIT + 40 and "[9924 characters]" in short, short
    assert shorten("Au") == "'Au'" and shorten_values("a 'b' c") == "a 'b' c"


@pytest.mark.parametrize("argv", [["--help"], ["fit", "--help"], ["render", "--help"]])
def test_help_exits_zero(argv, capsys):
    try:
        code = main(argv)
    except SystemExit as exc:                  # argparse's --help exits after printing
        code = exc.code
    assert code == 0 and "usage" in capsys.readouterr().out


def test_quiet_silences_progress_deep_in_the_library(capsys, monkeypatch):
    """``-q`` reaches work no command passes a callback to: the DHR table's build (its default
    progress=True means stderr lines) reports every chunk here (throttle period 0), and while
    quiet none of those reports reaches stderr."""
    import hyde_bsdf.progress as progress
    from hyde_bsdf.model import dhr

    calls = []

    def counted(value, prefix="[hyde-bsdf]"):
        real = progress.as_callback(value, prefix)
        return None if real is None else (lambda message: (calls.append(message), real(message)))

    monkeypatch.setattr(dhr, "as_callback", counted)
    monkeypatch.setattr(dhr, "Throttle", lambda callback, seconds=0.0: progress.Throttle(callback, 0.0))
    old = progress.set_quiet(True)
    try:
        dhr.build_table("none")
    finally:
        progress.set_quiet(old)
    assert len(calls) > 5 and "building DHR table (none)" in calls[0], calls[:2]
    assert capsys.readouterr().err == ""


def test_exceptions_become_messages_in_one_place():
    """Only ``hyde_bsdf/app/cli.py`` turns exceptions into stderr lines and exit codes: no other
    module of the package writes to stderr by hand (progress goes through hyde_bsdf.progress)
    or catches the package's UsageError to print it or return an exit code."""
    import ast
    from pathlib import Path

    root = Path(hyde_bsdf.__file__).resolve().parent
    allowed = {root / "app" / "cli.py", root / "progress.py"}
    bad = []
    for path in library_modules(root):
        if path in allowed:
            continue
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            text = ast.unparse(node) if isinstance(node, (ast.Call, ast.ExceptHandler)) else ""
            if isinstance(node, ast.Call) and ("sys.stderr" in text or "sys.stdout.write" in text):
                bad.append(f"{path.relative_to(root)}:{node.lineno}: writes to stderr")
            if isinstance(node, ast.ExceptHandler) and node.type is not None and "UsageError" in ast.unparse(node.type):
                body = ast.Module(body=node.body, type_ignores=[])
                if any(isinstance(n, ast.Return) and isinstance(n.value, ast.Constant) and type(n.value.value) is int
                       or isinstance(n, ast.Call) and ast.unparse(n.func) == "print" for n in ast.walk(body)):
                    bad.append(f"{path.relative_to(root)}:{node.lineno}: turns a UsageError into an exit code")
    assert not bad, bad


def test_library_usage_errors_reach_the_command_line_as_one_prefixed_line(tmp_path, capsys):
    """The library raises UsageError for a user's mistake (here: 1 measured value for 3 fitted
    parameters); app/ converts it in one place: exit status 2, one line, no traceback, and the
    fit's data errors still name the data file."""
    from hyde_bsdf.errors import UsageError
    from hyde_bsdf.fit.mueller_fit import fit_mueller

    a = np.radians([45.0])
    with pytest.raises(UsageError, match="too few data"):
        fit_mueller(a, a, np.array([np.pi]), {"M01": np.array([-0.1])}, fit="n,k,rms_slope", n0=1.5, k0=3.0)
    csv = tmp_path / "one.csv"
    csv.write_text("theta_i_deg,theta_r_deg,phi_deg,M01\n45,45,180,-0.1\n", encoding="utf-8")
    assert main(["fit", str(csv), "--fit", "n,k,rms_slope", "--n0", "1.5", "--k0", "3"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "Traceback" not in err[0]
    assert f"data file {str(csv)!r}: too few data to fit n, k, rms_slope" in err[0]


def test_every_flag_of_the_table_is_an_option_of_a_command():
    """The one table that turns the library's parameter names into flags (hyde_bsdf.app.flags) names
    only options some sub-command has, and the command line prints them: a library message
    'lower `spp`' reaches the user as 'lower --spp'."""
    import importlib

    from hyde_bsdf.app.cli import COMMANDS
    from hyde_bsdf.app.flags import FLAGS, for_command_line

    options = set()
    for module, _ in COMMANDS.values():
        mod = importlib.import_module(module)
        for name in ("build_parser", "csv_parser", "pbsdf_parser"):
            if hasattr(mod, name):
                options |= {o for a in getattr(mod, name)()._actions for o in a.option_strings}
    assert {flag.split()[0] for flag in FLAGS.values()} <= options
    assert for_command_line("lower `spp` or fewer `workers`; `partitions` stays") == \
        "lower --spp or fewer --workers; `partitions` stays"
