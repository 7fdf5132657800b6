"""The quick validation report builds, and every one of its checks passes (issue: one validation
command).  This runs every validation script in quick mode (about 2-3 minutes on 2 cores)."""
import csv

from hyde_bsdf.report.build import SECTIONS, build_report, cli_main


def test_quick_report_builds_and_all_checks_pass(tmp_path):
    ok, rows, seconds = build_report(tmp_path, quick=True, progress=False)
    failed = [f"[{r['script']}] {r['name']}: {r['value']} (tolerance {r['tolerance']})" for r in rows if not r["passed"]]
    assert not failed, "\n".join(failed)
    assert ok
    html = (tmp_path / "index.html").read_text()
    # every script ran and contributed checks; every figure is linked from the page
    scripts = {s for _, names in SECTIONS for s in names}
    assert {r["script"] for r in rows} == scripts
    pngs = sorted(p.name for p in tmp_path.glob("*.png"))
    assert len(pngs) >= len(scripts)
    for name in pngs:
        assert f"src='{name}'" in html
    assert "Machine" in html and "CPU" in html
    with open(tmp_path / "checks.csv", newline="") as fh:
        assert len(list(csv.DictReader(fh))) == len(rows)


def test_validate_cli_reports_missing_output_folder_argument_errors(capsys):
    """A bad option is an argparse error (exit 2), not a traceback."""
    try:
        cli_main(["--no-such-option"])
    except SystemExit as exc:
        assert exc.code == 2
    assert "usage" in capsys.readouterr().err
