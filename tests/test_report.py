"""The quick validation report: every validation script runs in quick mode and every one of its
checks passes (issue: one validation command); the report itself builds, links every figure and
keeps the previous report when interrupted.

Each script is its own test (one quick report of that script alone, built by ``build_report``),
so the two CI workers share them; the whole-report assembly is checked on a stand-in script.
"""
import csv

import pytest

from hyde_bsdf.app.cli import main
from hyde_bsdf.app.report.build import SECTIONS, build_report


def cli_main(argv):
    """``hyde-bsdf validate ARGV`` in this process (the dispatcher: one-line errors, exit codes)."""
    return main(["validate", *argv])

SCRIPTS = [(title, stem) for title, names in SECTIONS for stem in names]


@pytest.mark.parametrize("title,stem", SCRIPTS, ids=[stem for _, stem in SCRIPTS])
def test_quick_report_of_each_script_builds_and_all_checks_pass(title, stem, tmp_path, monkeypatch):
    monkeypatch.setattr("hyde_bsdf.app.report.build.SECTIONS", [(title, [stem])])
    ok, rows, seconds = build_report(tmp_path, quick=True, progress=False)
    failed = [f"[{r['script']}] {r['name']}: {r['value']} (tolerance {r['tolerance']})" for r in rows if not r["passed"]]
    assert not failed, "\n".join(failed)
    assert ok and rows and {r["script"] for r in rows} == {stem}
    html = (tmp_path / "index.html").read_text()
    pngs = sorted(p.name for p in tmp_path.glob("*.png"))
    assert pngs, f"{stem} wrote no figure"
    for name in pngs:
        assert f"src='{name}'" in html
    assert "Machine" in html and "CPU" in html
    with open(tmp_path / "checks.csv", newline="") as fh:
        assert len(list(csv.DictReader(fh))) == len(rows)


def test_every_validation_script_is_in_the_report():
    from pathlib import Path

    here = Path(__file__).resolve().parent.parent / "hyde_bsdf" / "validation"
    scripts = {p.stem for p in here.glob("*.py") if not p.stem.startswith("_") and p.stem != "plugin_report"}
    assert scripts == {stem for _, stem in SCRIPTS}, scripts ^ {stem for _, stem in SCRIPTS}


def test_validate_cli_reports_missing_output_folder_argument_errors(capsys):
    """A bad option is one line naming it, exit 2, not a traceback."""
    assert cli_main(["--no-such-option"]) == 2
    err = capsys.readouterr().err
    assert "unrecognized arguments: --no-such-option" in err and err.count("\n") == 1, err


FAKE_SCRIPT = '''"""A stand-in validation script: one figure, one CSV, one check."""
import os


def validate(outdir, quick=False):
    from _common import write_csv
    if os.environ.get("HYDE_TEST_INTERRUPT") == "1":
        open(os.path.join(outdir, "fake_new.png"), "wb").write(b"half")
        raise KeyboardInterrupt
    open(os.path.join(outdir, "fake.png"), "wb").write(b"\\x89PNG fake")
    write_csv(os.path.join(outdir, "fake.csv"), ["x"], [[1]])
    return [dict(name="fake check", value=1.0, tolerance="== 1", passed=True)]


if __name__ == "__main__":
    from _common import cli
    cli(validate, __doc__)
'''


def _fake_validation(tmp_path, monkeypatch):
    import shutil
    from pathlib import Path

    vdir = tmp_path / "validation"
    vdir.mkdir()
    (vdir / "fake_check.py").write_text(FAKE_SCRIPT)
    shutil.copy(Path(__file__).resolve().parent.parent / "hyde_bsdf" / "validation" / "_common.py", vdir / "_common.py")
    monkeypatch.setattr("hyde_bsdf.app.report.build.VALIDATION_DIR", vdir)
    monkeypatch.setattr("hyde_bsdf.app.report.build.SECTIONS", [("Fake", ["fake_check"])])
    monkeypatch.setattr("hyde_bsdf.app.report.build.machine_info", lambda: {"CPU": "test"})


def test_interrupted_report_keeps_previous_report(tmp_path, monkeypatch):
    """Issue 10: the report is built in a fresh folder and moved in at the end, so a run
    interrupted half-way (Ctrl-C inside a script) leaves the previous report -- its index.html
    and its figures -- exactly as it was, with no new figure beside it and no temporary folder."""
    _fake_validation(tmp_path, monkeypatch)
    out = tmp_path / "report"
    ok, rows, _ = build_report(out, quick=True, progress=False)
    assert ok and len(rows) == 1
    before = {p.name: p.read_bytes() for p in out.iterdir()}
    assert set(before) == {"index.html", "checks.csv", "times.csv", "fake.png", "fake.csv"}
    assert "1 of 1 checks pass" in before["index.html"].decode()
    monkeypatch.setenv("HYDE_TEST_INTERRUPT", "1")
    try:
        build_report(out, quick=True, progress=False)
    except KeyboardInterrupt:
        pass
    else:
        raise AssertionError("the interrupt did not reach build_report's caller")
    assert {p.name: p.read_bytes() for p in out.iterdir()} == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["report", "validation"]
    # A later complete run replaces the report's files.
    monkeypatch.delenv("HYDE_TEST_INTERRUPT")
    (out / "fake.csv").unlink()
    assert cli_main(["-o", str(out), "--quick"]) == 0
    assert {p.name for p in out.iterdir()} == set(before)


def test_report_never_deletes_a_users_files(tmp_path, monkeypatch, capsys):
    """Issue 15: ``validate -o DIR`` where DIR is a web site (an index.html the report did not
    write) is refused before any work (exit 2, one line naming the folder); ``--force`` writes the
    report beside the user's files, replacing only those of the report's names.  A user's file
    added to an earlier report's folder is kept by the next report."""
    _fake_validation(tmp_path, monkeypatch)
    site = tmp_path / "site"
    site.mkdir()
    (site / "index.html").write_text("<html>my thesis site</html>")
    (site / "notes.txt").write_text("keep me")
    assert cli_main(["-o", str(site), "--quick"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err == [f"hyde-bsdf validate: error: --outdir {str(site)!r} is not a validation report and holds 2 "
                   "file(s) ('index.html', 'notes.txt'); give a new or empty folder, or pass --force to write the "
                   "report beside them (files of the report's names are replaced)"]
    assert sorted(p.name for p in site.iterdir()) == ["index.html", "notes.txt"]
    assert cli_main(["-o", str(site), "--quick", "--force"]) == 0
    assert (site / "notes.txt").read_text() == "keep me"
    assert "1 of 1 checks pass" in (site / "index.html").read_text()
    report = tmp_path / "report"
    build_report(report, quick=True, progress=False)
    (report / "my_figure.png").write_bytes(b"mine")
    assert cli_main(["-o", str(report), "--quick"]) == 0
    assert (report / "my_figure.png").read_bytes() == b"mine"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["report", "site", "validation"]


# --- the report runs each script as a child process (issue 24: the package imports nothing outside itself) ---

#: fake scripts of the runner tests: STEM -> body of ``validate`` (each file gets the docstring
#: "STEM's docstring" and the protocol's ``__main__`` block)
FAKES = {
    "passing": "return [dict(name='np value', value=np.float64(0.25), tolerance='<= 1', passed=np.bool_(True))]",
    "failing": "return [dict(name='too big', value=3, tolerance='<= 1', passed=False)]",
    "crashing": "print('noise ' * 50, file=sys.stderr)\n    raise ValueError('boom: the fake crashed')",
    "killed": "os.kill(os.getpid(), signal.SIGKILL)",
    "chatty": ("for i in range(40000):\n        print('out', i, 'x' * 100)\n        print('err', i, 'y' * 100, "
               "file=sys.stderr)\n    return [dict(name='said a lot', value=40000, tolerance='any', passed=True)]"),
}


def _write_fakes(vdir, fakes):
    import shutil
    from pathlib import Path

    vdir.mkdir(exist_ok=True)
    shutil.copy(Path(__file__).resolve().parent.parent / "hyde_bsdf" / "validation" / "_common.py", vdir / "_common.py")
    for stem, body in fakes.items():
        (vdir / f"{stem}.py").write_text(
            f'"""{stem}\'s docstring."""\nimport os\nimport signal\nimport sys\n\nimport numpy as np\n\n\n'
            f"def validate(outdir, quick=False):\n    {body}\n\n\n"
            'if __name__ == "__main__":\n    from _common import cli\n    cli(validate, __doc__)\n')


def test_runner_reports_pass_fail_crash_kill_missing_and_chatty_scripts(tmp_path, monkeypatch):
    """Each script runs as a child process: its checks come back through ``--checks-json`` with
    their numbers (NumPy scalars as plain numbers) and its docstring; a script that raises or is
    killed (SIGKILL) is one failed check whose value is the exit status and the last stderr line,
    with the last TAIL_LINES lines of stderr as detail; a missing script is a failed check; a script
    that writes 9 MB to stdout and stderr does not block the report.  The report completes (exit 1)."""
    from hyde_bsdf.app.report import build

    vdir = tmp_path / "scripts"
    _write_fakes(vdir, FAKES)
    monkeypatch.setattr(build, "SECTIONS", [("Fake", [*FAKES, "absent"])])
    monkeypatch.setattr(build, "machine_info", lambda: {"CPU": "test"})
    ok, rows, _ = build_report(tmp_path / "report", quick=True, progress=False, scripts=vdir)
    got = {r["script"]: r for r in rows}
    assert not ok and len(rows) == len(FAKES) + 1
    assert got["passing"]["value"] == 0.25 and got["passing"]["passed"] is True
    assert got["failing"]["value"] == 3 and got["failing"]["passed"] is False
    assert got["crashing"]["name"] == "crashing: ran" and not got["crashing"]["passed"]
    assert got["crashing"]["value"] == "exit status 1: ValueError: boom: the fake crashed"
    assert got["killed"]["value"] == f"exit status {-__import__('signal').SIGKILL} (no output on stderr)"
    assert got["absent"]["name"] == "absent: script present" and got["absent"]["value"] == "missing"
    assert got["chatty"]["passed"] is True and got["chatty"]["value"] == 40000
    page = (tmp_path / "report" / "index.html").read_text()
    assert "passing&#x27;s docstring." in page and "chatty&#x27;s docstring." in page
    assert "Traceback (most recent call last)" in page and "noise noise" in page
    with open(tmp_path / "report" / "checks.csv", newline="") as fh:
        assert [r["passed"] for r in csv.DictReader(fh)] == ["True", "False", "False", "False", "True", "False"]


def test_no_state_passes_from_one_script_to_the_next(tmp_path, monkeypatch):
    """Isolation: a script that changes shared state (a global of the shared ``_common`` module, an
    environment variable, NumPy's error settings) leaves nothing for the script after it -- in
    the one-process report it did (the next script met the first one's module and settings)."""
    from hyde_bsdf.app.report import build

    vdir = tmp_path / "scripts"
    _write_fakes(vdir, {
        "dirty": "import _common\n    _common.LEAK = 1\n    os.environ['HYDE_LEAK'] = '1'\n"
                 "    np.seterr(all='raise')\n    return [dict(name='dirtied', value=1, tolerance='-', passed=True)]",
        "clean": "import _common\n    seen = [hasattr(_common, 'LEAK'), 'HYDE_LEAK' in os.environ, "
                 "np.geterr()['divide'] == 'raise']\n"
                 "    return [dict(name='nothing leaked', value=str(seen), tolerance='[False, False, False]', "
                 "passed=not any(seen))]"})
    monkeypatch.setattr(build, "SECTIONS", [("Fake", ["dirty", "clean"])])
    monkeypatch.setattr(build, "machine_info", lambda: {"CPU": "test"})
    ok, rows, _ = build_report(tmp_path / "report", quick=True, progress=False, scripts=vdir)
    assert ok and rows[1]["value"] == "[False, False, False]", rows


def test_a_crashed_scripts_detail_is_the_tail_of_its_stderr(tmp_path):
    """A crash after 5000 lines on stderr: the detail is the last TAIL_LINES lines (the traceback's
    end), not the whole 5000."""
    from hyde_bsdf.app.report.build import TAIL_LINES, _run_script

    _write_fakes(tmp_path, {"loud": "for i in range(5000):\n        print('line', i, file=sys.stderr)\n"
                                    "    raise RuntimeError('after the noise')"})
    checks, seconds, doc = _run_script(tmp_path / "loud.py", tmp_path, quick=True)
    assert len(checks) == 1 and not checks[0]["passed"] and doc == "" and seconds > 0
    detail = checks[0]["detail"].splitlines()
    assert len(detail) == TAIL_LINES and detail[-1] == "RuntimeError: after the noise"
    assert "line 4999" in checks[0]["detail"] and "line 4000" not in checks[0]["detail"]


def test_a_script_without_the_protocol_is_a_failed_check_that_says_why(tmp_path):
    """A script whose ``__main__`` block does not go through ``_common.cli`` (or that has none) ends
    with status 0 and no checks: one failed check saying so, not a silent pass."""
    from hyde_bsdf.app.report.build import _run_script

    (tmp_path / "bare.py").write_text('"""No __main__ block."""\ndef validate(outdir, quick=False):\n    return []\n')
    checks, _, _ = _run_script(tmp_path / "bare.py", tmp_path, quick=True)
    assert [(c["name"], c["passed"]) for c in checks] == [("bare: ran", False)]
    assert checks[0]["value"].startswith("exit status 0 (no output on stderr), and no checks came back")


def test_ctrl_c_terminates_the_running_script(tmp_path):
    """Ctrl-C (SIGINT to the report's process only: here the script itself sends it to its parent,
    then sleeps) interrupts the report with KeyboardInterrupt, and the child is terminated and
    reaped before the interrupt goes on: no script keeps running after the report ends."""
    from hyde_bsdf.app.report.build import _run_script

    _write_fakes(tmp_path, {"sleeper": "open(os.path.join(outdir, 'pid'), 'w').write(str(os.getpid()))\n"
                                       "    os.kill(os.getppid(), signal.SIGINT)\n    while True:\n"
                                       "        signal.pause()"})
    with pytest.raises(KeyboardInterrupt):
        _run_script(tmp_path / "sleeper.py", tmp_path, quick=True)
    pid = int((tmp_path / "pid").read_text())
    with pytest.raises(ProcessLookupError):       # terminated and reaped (not a zombie)
        __import__("os").kill(pid, 0)


#: a fake script's body that writes OUTDIR/STEM.started, then waits (at most 60 s) for OUTDIR/OTHER.started
MEET = ("open(os.path.join(outdir, '{me}.started'), 'w').close()\n"
        "    import time\n    t0 = time.monotonic()\n"
        "    while not os.path.exists(os.path.join(outdir, '{other}.started')) and time.monotonic() - t0 < 60:\n"
        "        time.sleep(0.02)\n"
        "    met = os.path.exists(os.path.join(outdir, '{other}.started'))\n"
        "    import matplotlib\n    matplotlib.use('Agg')\n    import matplotlib.pyplot as plt\n"
        "    from _common import save_figure\n    save_figure(plt.figure(), os.path.join(outdir, '{me}.png'))\n"
        "    return [dict(name='ran beside {other}', value=met, tolerance='True', passed=met)]")


def test_scripts_run_side_by_side_and_each_keeps_its_own_figures(tmp_path, monkeypatch):
    """``jobs=2``: two scripts run at the same time (each waits for the other to have started: one
    after the other, both would wait in vain), yet the report lists the checks in the sections'
    order and under each script only the figure that script saved (the protocol's "figures", not
    whatever appeared in the shared folder meanwhile), with its CPU time."""
    from hyde_bsdf.app.report import build

    vdir = tmp_path / "scripts"
    _write_fakes(vdir, {"left": MEET.format(me="left", other="right"), "right": MEET.format(me="right", other="left")})
    monkeypatch.setattr(build, "SECTIONS", [("Fake", ["left", "right"])])
    monkeypatch.setattr(build, "machine_info", lambda: {"CPU": "test"})
    ok, rows, _ = build_report(tmp_path / "report", quick=True, progress=False, scripts=vdir, jobs=2)
    assert ok and [r["script"] for r in rows] == ["left", "right"], rows
    page = (tmp_path / "report" / "index.html").read_text()
    left, right = page.split("<h3>left")[1].split("<h3>right")
    assert "src='left.png'" in left and "right.png" not in left
    assert "src='right.png'" in right and "left.png" not in right
    assert left.count("CPU s)") == 1 and right.count("CPU s)") == 1


def test_side_by_side_scripts_share_the_cores_in_blas_and_drjit(tmp_path, monkeypatch):
    """``jobs=2``: each script gets cores // 2 threads (at least 1) in BLAS and OpenMP and in Dr.Jit's pool --
    which reads no environment variable: the protocol (``_common.cli``) sizes it from HYDE_DRJIT_THREADS.  With
    Dr.Jit's default pool (a thread per core) two small-kernel scripts at once spent 24 CPU s where one thread
    each spends 15 (capture_camera --quick, docs/validation.md).  A user's own OMP_NUM_THREADS is kept."""
    import os

    from hyde_bsdf.app.report import build

    monkeypatch.setenv("OMP_NUM_THREADS", "3")
    monkeypatch.delenv("HYDE_DRJIT_THREADS", raising=False)
    vdir = tmp_path / "scripts"
    _write_fakes(vdir, {"threads": "import drjit\n    got = [drjit.thread_count(), os.environ['OMP_NUM_THREADS'], "
                                   "os.environ['OPENBLAS_NUM_THREADS']]\n"
                                   "    return [dict(name='threads', value=str(got), tolerance='-', passed=True)]"})
    monkeypatch.setattr(build, "SECTIONS", [("Fake", ["threads"])])
    monkeypatch.setattr(build, "machine_info", lambda: {"CPU": "test"})
    ok, rows, _ = build_report(tmp_path / "report", quick=True, progress=False, scripts=vdir, jobs=2)
    share = max(1, (os.cpu_count() or 1) // 2)
    assert ok and rows[0]["value"] == str([share, "3", str(share)]), rows


def test_a_script_that_reads_anothers_output_waits_for_it(tmp_path, monkeypatch):
    """A script of ``AFTER`` (mom_1d_model reads fig6_mom's run) starts only once the script it
    reads has ended, whatever the number of scripts at once; the others do not wait."""
    from hyde_bsdf.app.report import build

    vdir = tmp_path / "scripts"
    _write_fakes(vdir, {
        "writer": "import time\n    time.sleep(1.0)\n    open(os.path.join(outdir, 'run.txt'), 'w').write('done')\n"
                  "    return [dict(name='wrote', value=1, tolerance='-', passed=True)]",
        "reader": "p = os.path.join(outdir, 'run.txt')\n    got = open(p).read() if os.path.exists(p) else 'nothing'\n"
                  "    return [dict(name='read the writer', value=got, tolerance='done', passed=got == 'done')]"})
    monkeypatch.setattr(build, "SECTIONS", [("Fake", ["writer", "reader"])])
    monkeypatch.setattr(build, "AFTER", {"reader": "writer"})
    monkeypatch.setattr(build, "machine_info", lambda: {"CPU": "test"})
    ok, rows, _ = build_report(tmp_path / "report", quick=True, progress=False, scripts=vdir, jobs=2)
    assert ok and rows[1]["value"] == "done", rows


def test_a_rerun_starts_the_longest_scripts_first(tmp_path, monkeypatch):
    """The report writes each script's wall and CPU seconds to times.csv; a rerun into the same
    folder starts the scripts that took the most CPU time first (a script it has no time for before
    them), so that no long script runs alone at the end.  The report's order stays the sections'."""
    from hyde_bsdf.app.report import build

    vdir = tmp_path / "scripts"
    _write_fakes(vdir, {stem: "return [dict(name='ok', value=1, tolerance='-', passed=True)]" for stem in "abc"})
    monkeypatch.setattr(build, "SECTIONS", [("Fake", ["a", "b", "c"])])
    monkeypatch.setattr(build, "machine_info", lambda: {"CPU": "test"})
    out = tmp_path / "report"
    build_report(out, quick=True, progress=False, scripts=vdir, jobs=1)
    with open(out / "times.csv", newline="") as fh:
        times = list(csv.DictReader(fh))
    assert [r["script"] for r in times] == ["a", "b", "c"] and all(float(r["cpu_seconds"]) > 0 for r in times)
    (out / "times.csv").write_text("script,mode,seconds,cpu_seconds,jobs\na,quick,1,1.0,1\nb,quick,9,9.0,1\n")
    started = []
    ok, rows, _ = build_report(out, quick=True, progress=lambda m: started.append(m.split()[1]) if "..." in m else None,
                               scripts=vdir, jobs=1)
    assert started == ["c", "b", "a"] and [r["script"] for r in rows] == ["a", "b", "c"]


def test_ctrl_c_terminates_every_running_script(tmp_path):
    """Two scripts at once: Ctrl-C (the second script sends SIGINT to the report once both run)
    interrupts the report, and both children are terminated and reaped."""
    from hyde_bsdf.app.report.build import _run_all

    sleep = "    while True:\n        signal.pause()"
    _write_fakes(tmp_path, {
        "one": "open(os.path.join(outdir, 'one.tmp'), 'w').write(str(os.getpid()))\n"
               "    os.replace(os.path.join(outdir, 'one.tmp'), os.path.join(outdir, 'one.pid'))\n" + sleep,
        "two": "open(os.path.join(outdir, 'two.pid'), 'w').write(str(os.getpid()))\n"
               "    while not os.path.exists(os.path.join(outdir, 'one.pid')):\n        pass\n"
               "    os.kill(os.getppid(), signal.SIGINT)\n" + sleep})
    with pytest.raises(KeyboardInterrupt):
        _run_all([tmp_path / "one.py", tmp_path / "two.py"], tmp_path, quick=True, jobs=2)
    for name in ("one.pid", "two.pid"):
        with pytest.raises(ProcessLookupError):       # terminated and reaped (not a zombie)
            __import__("os").kill(int((tmp_path / name).read_text()), 0)


def test_jobs_must_be_a_whole_number_of_at_least_one(tmp_path, capsys):
    """``--jobs 0`` is one line naming the option, exit 2, before any work."""
    assert cli_main(["-o", str(tmp_path / "r"), "--jobs", "0"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--jobs" in err[0] and "expected an integer >= 1, got 0" in err[0], err
    assert not (tmp_path / "r").exists()


def test_scripts_option_names_the_folder_and_refuses_one_without_scripts(tmp_path, capsys):
    """``validate --scripts DIR`` (an installed package: a clone's hyde_bsdf/validation/ folder): a folder
    without the report's scripts is refused before any work, exit 2, in one line naming it."""
    empty = tmp_path / "empty"
    empty.mkdir()
    assert cli_main(["-o", str(tmp_path / "r"), "--scripts", str(empty)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and f"--scripts {str(empty)!r} holds none of the validation scripts" in err[0], err
    assert not (tmp_path / "r").exists()


#: what loads a file as code: a package that uses none of these runs no file outside itself
LOADERS = {"spec_from_file_location", "SourceFileLoader", "module_from_spec", "exec_module", "load_module",
           "run_path", "run_module", "exec", "execfile"}


def _loads_files(source: str) -> list:
    """(line, name) of every use of a file loader, and of every change to ``sys.path``."""
    import ast

    found = []
    for node in ast.walk(ast.parse(source)):
        name = node.attr if isinstance(node, ast.Attribute) else node.id if isinstance(node, ast.Name) else None
        if name in LOADERS:
            found.append((node.lineno, name))
        if isinstance(node, ast.Attribute) and node.attr == "path" and getattr(node.value, "id", "") == "sys":
            found.append((node.lineno, "sys.path"))
    return found


def test_the_package_loads_no_file_outside_itself():
    """Layering (issue 24): ``hyde_bsdf`` imports only modules by name; no module of it loads a
    file as code (importlib's file loaders, runpy, exec) or changes ``sys.path`` -- the report runs
    the validation scripts as child processes (that nothing below them imports them is the top
    layer's rule, tests/test_layers.py)."""
    from pathlib import Path

    package = Path(__file__).resolve().parent.parent / "hyde_bsdf"
    found = {str(p.relative_to(package)): _loads_files(p.read_text(encoding="utf-8"))
             for p in sorted(package.rglob("*.py"))}
    assert {k: v for k, v in found.items() if v} == {}


def test_the_loader_check_catches_the_old_in_process_loader():
    """The check above sees what the report did before: insert the scripts' folder into sys.path
    and load a script through importlib."""
    old = ("import importlib.util, sys\n"
           "def _load(path):\n    sys.path.insert(0, str(path.parent))\n"
           "    spec = importlib.util.spec_from_file_location(path.stem, path)\n"
           "    module = importlib.util.module_from_spec(spec)\n    spec.loader.exec_module(module)\n")
    assert {name for _, name in _loads_files(old)} == {"sys.path", "spec_from_file_location", "module_from_spec",
                                                      "exec_module"}
