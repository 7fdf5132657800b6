"""``hyde-bsdf validate [--quick] -o DIR``: run every validation script, write one report.

Each script in ``validation/`` exposes ``validate(outdir, quick=False)`` returning a list of checks
``dict(name, value, tolerance, passed)`` and writes its PNG and CSV files into ``outdir``.  This
module runs them in order (in this process, so each one's time is measured), collects the checks
and the figures, and writes ``DIR/index.html`` (and ``DIR/checks.csv``): the machine, the time
each script took, a table of every check with its number, tolerance and verdict, and the figures.
A script that raises is reported as a failed check with its message; the report still completes.
Exit status: 0 when every check passes, 1 otherwise, 2 for a usage error (an output folder that
cannot be written or holds files an earlier report did not write, no ``validation/`` scripts:
not a source checkout).

Nothing but an earlier report's own files is ever deleted.  The report is built in a fresh hidden
folder beside ``DIR`` and moved in at the end (:func:`hyde_bsdf.io.atomic.atomic_dir`), with a
manifest ``DIR/.hyde-report-manifest.json`` listing every file it wrote, with its SHA-256, and
every folder it created: an interrupted run
(Ctrl-C, SIGTERM, a kill) leaves the previous report as it was, never an old ``index.html``
beside new figures.  ``DIR`` must be new, empty, or hold only an earlier report's files (those its
manifest lists, unchanged since: same SHA-256, reached without a symlink); a folder with any other
file or folder -- a web site's ``index.html``, a thesis, an empty folder tree, a file edited since
-- is refused before any work, unless ``--force``: then the unchanged files of the earlier report
are replaced and everything else is kept (one whose name the report takes, such as
``index.html``, is renamed ``index.html.orig``).  Symlinks are never followed and no folder the
report did not create is removed.  A report without a manifest (or from before manifests had
hashes) is not adopted: that its HTML names a file does not prove the report wrote it.
"""
from __future__ import annotations

import argparse
import csv
import datetime as _dt
import html
import importlib.util
import os
import platform
import sys
import time
import traceback
import warnings
from pathlib import Path

from hyde_bsdf.io.atomic import (TEMP_NAME_RE, atomic_dir, atomic_open, check_dir_owned, folder_target,
                                 check_output_dir, read_manifest)
from hyde_bsdf.app.args import Parser, quiet_option
from hyde_bsdf.errors import UsageError
from hyde_bsdf.io.memory import format_bytes, total_bytes
from hyde_bsdf.progress import as_callback

__all__ = ["SECTIONS", "MANIFEST", "build_report", "check_report_dir", "cli_main"]

#: (section title, [validation script stems]) in report order
SECTIONS = [
    ("NumPy evaluator and DHR (paper Figs. 4, 8, 9; Eqs. 6-17)",
     ["fig4_priest_germer", "fig8_9_mueller", "dhr_convergence", "stability_evaluator"]),
    ("Mitsuba plugin and rendering",
     ["plugin_checks", "render_checks", "speed_accuracy_render", "model_economy"]),
    ("Method of moments (paper Fig. 6)", ["fig6_mom", "mom_convergence", "mom_1d_model", "stability_mom", "mom_polarization", "mom_mueller_1d", "mom_speed_accuracy", "mom_grazing", "mom_forward_grazing"]),
    ("Fitting and inverse rendering (paper Section 4)",
     ["fit_synthetic", "fit_model_selection", "inverse_render", "gradient_check", "svbrdf_inverse", "svbrdf_index",
      "capture_camera", "pbsdf_export"]),
]


#: Where the validation scripts live: ``validation/`` of the source checkout this package is in.
VALIDATION_DIR = Path(__file__).resolve().parents[3] / "validation"


def validation_dir() -> Path:
    """The validation scripts' folder; UsageError when this is not a source checkout."""
    here = Path(VALIDATION_DIR)
    missing = [f"{stem}.py" for _, names in SECTIONS for stem in names if not (here / f"{stem}.py").is_file()]
    if not here.is_dir() or len(missing) == sum(len(n) for _, n in SECTIONS):
        raise UsageError(f"validate needs the validation/ scripts of a source checkout, and {str(here)!r} "
                         "has none (an installed package does not ship them): clone the repository and "
                         "run 'pip install -e .' and 'hyde-bsdf validate' there")
    return here


#: the manifest of a report folder: every file the report wrote (a rerun removes only these)
MANIFEST = ".hyde-report-manifest.json"


def check_report_dir(outdir, force: bool = False) -> Path:
    """Check before any work that ``outdir`` can take a report (UsageError otherwise).

    Refused: a regular file, the current folder or one above it, and -- unless ``force`` -- a
    folder holding files that no earlier report wrote (see the module docstring).
    """
    out = folder_target(outdir, "--outdir", follow_link=True)
    here = Path.cwd().resolve()
    if out.resolve() == here or out.resolve() in here.parents:
        raise UsageError(f"--outdir {str(outdir)!r} is the current folder or one above it: give the report "
                         "a folder of its own (default out/report)")
    # a report written before manifests (or one whose manifest has no hashes) is not adopted: that
    # its HTML names a file does not prove this program wrote it (it may be the user's image)
    if out.is_dir():
        others = [f for f in (p.name for p in out.iterdir()) if f != MANIFEST and not TEMP_NAME_RE.match(f)]
        if others and read_manifest(out, MANIFEST) is None and not force:
            shown = ", ".join(repr(f) for f in sorted(others)[:3]) + (" ..." if len(others) > 3 else "")
            raise UsageError(f"--outdir {str(out)!r} is not a validation report (no {MANIFEST}) and holds "
                             f"{len(others)} file(s) ({shown}); give a new or empty folder, or pass --force to "
                             "write the report beside them (they are kept)")
        check_dir_owned(out, MANIFEST, force, "--outdir")
    check_output_dir(out.parent, "--outdir's parent folder")
    return out


def machine_info() -> dict:
    info = {"date (UTC)": _dt.datetime.now(_dt.timezone.utc).strftime("%Y-%m-%d %H:%M"),
            "host": platform.node(), "OS": platform.platform(), "python": platform.python_version(),
            "cores": str(os.cpu_count())}
    try:
        cpu = next(line.split(":", 1)[1].strip() for line in open("/proc/cpuinfo") if line.startswith("model name"))
        info["CPU"] = cpu
    except (OSError, StopIteration):
        info["CPU"] = platform.processor() or platform.machine()
    if total_bytes() is not None:
        info["memory"] = format_bytes(total_bytes())
    info["load average at start"] = f"{os.getloadavg()[0]:.2f}"
    for mod in ("numpy", "scipy", "matplotlib", "mitsuba", "drjit"):
        try:
            info[mod] = __import__(mod).__version__
        except Exception as exc:  # noqa: BLE001 -- report, don't crash
            info[mod] = f"unavailable ({exc})"
    try:
        from hyde_bsdf.mitsuba.variants import llvm_usable
        info["Dr.Jit LLVM"] = llvm_usable()[1]
    except Exception as exc:  # noqa: BLE001
        info["Dr.Jit LLVM"] = f"unknown ({exc})"
    return info


def _load(path: Path):
    if str(path.parent) not in sys.path:      # scripts import their siblings by name
        sys.path.insert(0, str(path.parent))
    spec = importlib.util.spec_from_file_location(path.stem, path)
    module = importlib.util.module_from_spec(spec)
    sys.modules[path.stem] = module           # dataclasses look their module up here
    spec.loader.exec_module(module)
    return module


def _run_script(path: Path, outdir: Path, quick: bool):
    if not path.exists():
        return [dict(name=f"{path.stem}: script present", value="missing", tolerance="present",
                     passed=False)], 0.0, ""
    t0 = time.perf_counter()
    try:
        module = _load(path)
        checks = list(module.validate(str(outdir), quick=quick))
        doc = (module.__doc__ or "").strip()
    except Exception as exc:  # noqa: BLE001 -- a failing script is a failed check, not a crash
        tb = traceback.format_exc(limit=3)
        checks = [dict(name=f"{path.stem}: ran", value=f"{type(exc).__name__}: {exc}", tolerance="no error",
                       passed=False, detail=tb)]
        doc = ""
    return checks, time.perf_counter() - t0, doc


def _fmt(v):
    if isinstance(v, float):
        return f"{v:.4g}"
    return html.escape(str(v))


def build_report(outdir, quick=False, progress=True, force=False):
    """Run all scripts into ``outdir``; return (all_passed, rows, seconds).

    The report is built in a fresh folder and moved into ``outdir`` only once complete (see the
    module docstring); UsageError before any work for an unusable ``outdir`` (one holding files
    an earlier report did not write, unless ``force``) or no scripts.
    """
    final = check_report_dir(outdir, force)
    vdir = validation_dir()

    def kept(paths):
        warnings.warn("kept your file(s) the report's names would replace as: " + ", ".join(str(p) for p in paths),
                      UserWarning, stacklevel=2)

    with atomic_dir(final, manifest=MANIFEST, force=force, on_kept=kept) as out:
        result = _build(out, vdir, quick, as_callback(progress, "[validate]"))
    return result


def _build(out: Path, vdir: Path, quick: bool, progress: bool):
    info = machine_info()
    t_start = time.perf_counter()
    rows, sections = [], []
    scripts = [s for _, names in SECTIONS for s in names]
    done = 0
    for title, names in SECTIONS:
        entries = []
        for stem in names:
            if progress:
                progress(f"{done + 1}/{len(scripts)} {stem} ...")
            before = set(out.glob("*.png"))
            checks, seconds, doc = _run_script(vdir / f"{stem}.py", out, quick)
            figures = sorted(set(out.glob("*.png")) - before)
            if progress:
                bad = sum(not c["passed"] for c in checks)
                progress(f"   {seconds:.1f} s, {len(checks)} checks, {bad} failed")
            for c in checks:
                rows.append(dict(script=stem, **{k: c.get(k, "") for k in ("name", "value", "tolerance", "passed")}))
            entries.append((stem, doc, seconds, checks, figures))
            done += 1
        sections.append((title, entries))
    total = time.perf_counter() - t_start
    info["report run time"] = f"{total:.0f} s ({'quick' if quick else 'full'} mode)"
    all_passed = all(r["passed"] for r in rows)
    _write_html(out, info, sections, rows, all_passed, quick)
    with atomic_open(out / "checks.csv", "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=["script", "name", "value", "tolerance", "passed"])
        w.writeheader()
        w.writerows(rows)
    return all_passed, rows, total


def _write_html(out, info, sections, rows, all_passed, quick):
    n_fail = sum(not r["passed"] for r in rows)
    parts = [
        "<!doctype html><html><head><meta charset='utf-8'><title>hyde-bsdf validation report</title>",
        "<style>body{font-family:sans-serif;max-width:1100px;margin:auto;padding:1em}"
        "table{border-collapse:collapse;font-size:13px}td,th{border:1px solid #ccc;padding:3px 6px}"
        ".pass{color:#1a7f1a;font-weight:bold}.fail{color:#c00;font-weight:bold}"
        "img{max-width:100%;border:1px solid #ddd;margin:6px 0}pre{white-space:pre-wrap;font-size:12px;"
        "background:#f6f6f6;padding:6px}</style></head><body>",
        "<h1>hyde-bsdf validation report</h1>",
        f"<p>{'Quick' if quick else 'Full'} run: <span class='{'pass' if all_passed else 'fail'}'>"
        f"{len(rows) - n_fail} of {len(rows)} checks pass</span>.</p>",
        "<h2>Machine</h2><table>",
    ]
    parts += [f"<tr><th>{html.escape(k)}</th><td>{html.escape(str(v))}</td></tr>" for k, v in info.items()]
    parts.append("</table><h2>All checks</h2><table><tr><th>script</th><th>check</th><th>value</th>"
                 "<th>tolerance</th><th>verdict</th></tr>")
    for r in rows:
        verdict = "<span class='pass'>pass</span>" if r["passed"] else "<span class='fail'>FAIL</span>"
        parts.append(f"<tr><td>{r['script']}</td><td>{html.escape(str(r['name']))}</td><td>{_fmt(r['value'])}</td>"
                     f"<td>{_fmt(r['tolerance'])}</td><td>{verdict}</td></tr>")
    parts.append("</table>")
    for title, entries in sections:
        parts.append(f"<h2>{html.escape(title)}</h2>")
        for stem, doc, seconds, checks, figures in entries:
            parts.append(f"<h3>{stem} <small>({seconds:.1f} s)</small></h3>")
            if doc:
                parts.append(f"<pre>{html.escape(doc)}</pre>")
            for c in checks:
                if c.get("detail"):
                    parts.append(f"<pre>{html.escape(c['detail'])}</pre>")
            for fig in figures:
                parts.append(f"<img src='{html.escape(fig.name)}' alt='{html.escape(fig.stem)}'>")
    parts.append("</body></html>")
    with atomic_open(out / "index.html", "w", encoding="utf-8") as f:
        f.write("\n".join(parts))


def build_parser() -> Parser:
    ap = Parser(prog="hyde-bsdf validate", description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("-o", "--outdir", default="out/report", help="report folder (default out/report)")
    ap.add_argument("--quick", action="store_true", help="small sweeps; under 3 minutes on 2 cores")
    ap.add_argument("--force", action="store_true",
                    help="write into a folder that holds files no earlier report wrote; they are kept "
                         "(a file whose name the report takes is renamed NAME.orig)")
    quiet_option(ap)
    return ap


def cli_main(argv=None) -> int:
    """``hyde-bsdf validate``: 0 when every check passes, 1 otherwise; user errors raise UsageError."""
    a = build_parser().parse_args(argv)
    ok, rows, seconds = build_report(a.outdir, quick=a.quick, force=a.force, progress=not a.quiet)
    n_fail = sum(not r["passed"] for r in rows)
    print(f"{len(rows) - n_fail} of {len(rows)} checks pass in {seconds:.0f} s; report: {Path(a.outdir) / 'index.html'}")
    for r in rows:
        if not r["passed"]:
            print(f"  FAIL [{r['script']}] {r['name']}: {r['value']} (tolerance {r['tolerance']})")
    return 0 if ok else 1
