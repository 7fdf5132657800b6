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

    here = Path(__file__).resolve().parent.parent / "validation"
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
'''


def _fake_validation(tmp_path, monkeypatch):
    import shutil
    from pathlib import Path

    vdir = tmp_path / "validation"
    vdir.mkdir()
    (vdir / "fake_check.py").write_text(FAKE_SCRIPT)
    shutil.copy(Path(__file__).resolve().parent.parent / "validation" / "_common.py", vdir / "_common.py")
    monkeypatch.setattr("hyde_bsdf.app.report.build.VALIDATION_DIR", vdir)
    monkeypatch.setattr("hyde_bsdf.app.report.build.SECTIONS", [("Fake", ["fake_check"])])
    monkeypatch.setattr("hyde_bsdf.app.report.build.machine_info", lambda: {"CPU": "test"})


def test_interrupted_report_keeps_previous_report(tmp_path, monkeypatch):
    """Issue 10: the report is built in a fresh folder and swapped in at the end, so a run
    interrupted half-way (Ctrl-C inside a script) leaves the previous report -- its index.html
    and its figures -- exactly as it was, with no new figure beside it and no temporary folder."""
    _fake_validation(tmp_path, monkeypatch)
    out = tmp_path / "report"
    ok, rows, _ = build_report(out, quick=True, progress=False)
    assert ok and len(rows) == 1
    before = {p.name: p.read_bytes() for p in out.iterdir()}
    assert set(before) == {"index.html", "checks.csv", "fake.png", "fake.csv", ".hyde-report-manifest.json"}
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
    # A later complete run replaces the report's own files, and only those (issue 15).
    monkeypatch.delenv("HYDE_TEST_INTERRUPT")
    (out / "fake.csv").unlink()               # a report file gone: still the earlier report's folder
    assert cli_main(["-o", str(out), "--quick"]) == 0
    assert {p.name for p in out.iterdir()} == set(before)


def test_report_never_deletes_a_users_files(tmp_path, monkeypatch, capsys):
    """Issue 15: ``validate -o DIR`` where DIR is a web site (index.html, no manifest) or an earlier
    report with a user's file added is refused before any work (exit 2, one line naming the
    folder); ``--force`` writes the report beside the user's files and keeps them all (the
    site's index.html as index.html.orig); a report from before manifests is still recognised."""
    _fake_validation(tmp_path, monkeypatch)
    site = tmp_path / "site"
    site.mkdir()
    (site / "index.html").write_text("<html>my thesis site</html>")
    (site / "notes.txt").write_text("keep me")
    assert cli_main(["-o", str(site), "--quick"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err == [f"hyde-bsdf validate: error: --outdir {str(site)!r} is not a validation report (no "
                   ".hyde-report-manifest.json) and holds 2 file(s) ('index.html', 'notes.txt'); give a new or "
                   "empty folder, or pass --force to write the report beside them (they are kept)"]
    assert sorted(p.name for p in site.iterdir()) == ["index.html", "notes.txt"]
    assert cli_main(["-o", str(site), "--quick", "--force"]) == 0
    assert (site / "index.html.orig").read_text() == "<html>my thesis site</html>"
    assert (site / "notes.txt").read_text() == "keep me"
    assert "1 of 1 checks pass" in (site / "index.html").read_text()
    # an earlier report plus a user's file: refused again without --force
    report = tmp_path / "report"
    build_report(report, quick=True, progress=False)
    (report / "my_figure.png").write_bytes(b"mine")
    assert cli_main(["-o", str(report), "--quick"]) == 2
    assert "holds 1 file(s) that no earlier run wrote ('my_figure.png'; its manifest does not list" \
        in capsys.readouterr().err
    # a report written before manifests: index.html title + checks.csv header make it ours
    (report / "my_figure.png").unlink()
    (report / ".hyde-report-manifest.json").unlink()
    assert cli_main(["-o", str(report), "--quick"]) == 0
    assert sorted(p.name for p in tmp_path.iterdir()) == ["report", "site", "validation"]
