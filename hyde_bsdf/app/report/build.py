"""``hyde-bsdf validate [--quick] [--jobs N] [--scripts DIR] -o DIR``: run every validation script, write one report.

Each script in ``hyde_bsdf/validation/`` has ``validate(outdir, quick=False)`` returning a list of checks
``dict(name, value, tolerance, passed)`` and writes its PNG and CSV files into ``outdir``.  This
module runs them, each as a **child process** -- ``python SCRIPT.py -o OUT [--quick]
--checks-json FILE``, the protocol that ``hyde_bsdf/validation/_common.py`` handles once for every script
(the child writes its docstring, its checks, the figures it saved and its CPU time as JSON to
``FILE``) -- ``--jobs N`` of them at once (default one per core, at most :data:`MAX_JOBS`), times
each one, collects the checks and the figures, and writes ``DIR/index.html`` (and
``DIR/checks.csv``, and each script's wall and CPU seconds in ``DIR/times.csv``): the machine, the
time each script took, a table of every check with its
number, tolerance and verdict, and the figures, in the sections' order whatever order the scripts
ended in.  A script that reads another's output (:data:`AFTER`) starts after it.  The scripts that
took the most CPU time start first: as measured by the earlier report in the same folder, else by the
one shipped with the package (:data:`MEASURED_TIMES`).  A script that
crashes, is killed or is missing is reported as a failed check (with the last lines of its
stderr); the report still completes.  A script's own output is not shown (run it alone to see it:
``python hyde_bsdf/validation/STEM.py --quick``).  Ctrl-C (or SIGTERM) ends the running scripts
(SIGTERM, then SIGKILL) and the report, which leaves the previous report as it was.
Exit status: 0 when every check passes, 1 otherwise, 2 for a usage error (an output folder that
cannot be written or is not a report's, no validation scripts where ``--scripts DIR`` points).

Why child processes: **isolation** -- one script's Dr.Jit/Mitsuba state (the variant, JIT
caches, registered plugins) and its memory cannot leak into the next, so a check cannot pass or
fail because of the scripts that ran before it (an order-dependent failure class the in-process
report had); and **layering** -- the package loads no file as code: the scripts are files it
runs, not modules it loads.  The price is one interpreter start and its imports per script
(about 1 CPU s each); the gain, besides, is that scripts run side by side: most of them are
single-threaded Python and NumPy, so several at once keep every core busy (docs/validation.md,
"The report's run time").  With several at once, BLAS and OpenMP get their share of
the cores (:data:`THREAD_VARIABLES`); a time ratio a check reports is measured inside one script.

Nothing is ever deleted.  The report is built in a fresh hidden folder beside ``DIR`` and its
files are moved into ``DIR`` at the end, one rename each (:func:`hyde_bsdf.io.atomic.atomic_folder`):
an interrupted run (Ctrl-C, SIGTERM) leaves the previous report as it was.  ``DIR`` must be new,
empty, or an earlier report (its ``index.html`` carries the report's generator tag); any other
folder -- a web site's, a thesis's -- is refused before any work, unless ``--force``: then the
report's files are written beside the others, replacing those of the same names.
"""
from __future__ import annotations

import argparse
import csv
import datetime as _dt
import html
import json
import math
import os
import platform
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from hyde_bsdf.app.args import Parser, positive_int, quiet_option, reads, writes
from hyde_bsdf.errors import UsageError
from hyde_bsdf.io.atomic import TEMP_NAME_RE, atomic_folder, atomic_open
from hyde_bsdf.io.output_gate import check_not_input, check_output_dir
from hyde_bsdf.progress import as_callback
from hyde_bsdf.resources import OutputLock, format_bytes, total_memory, wait_limit

__all__ = ["SECTIONS", "GENERATOR", "build_report", "check_report_dir", "cli_main"]

#: (section title, [validation script stems]) in report order
SECTIONS = [
    ("NumPy evaluator and DHR (paper Figs. 4, 8, 9; Eqs. 6-17)",
     ["fig4_priest_germer", "fig8_9_mueller", "dhr_convergence", "stability_evaluator"]),
    ("Mitsuba plugin and rendering",
     ["plugin_checks", "render_checks", "furnace", "speed_accuracy_render", "model_economy"]),
    ("Method of moments (paper Fig. 6)", ["fig6_mom", "mom_convergence", "mom_1d_model", "stability_mom", "mom_polarization", "mom_mueller_1d", "mom_speed_accuracy", "mom_grazing", "mom_forward_grazing", "mom_reciprocity", "accuracy_atlas"]),
    ("Fitting and inverse rendering (paper Section 4)",
     ["fit_synthetic", "fit_model_selection", "fit_lab_data", "inverse_render", "gradient_check", "svbrdf_inverse", "svbrdf_index",
      "capture_camera", "pbsdf_export"]),
]


#: Where the validation scripts live by default: the package's own ``hyde_bsdf/validation/`` (shipped in
#: the wheel; ``--scripts DIR`` names another folder, e.g. a clone's newer scripts)
VALIDATION_DIR = Path(__file__).resolve().parents[2] / "validation"
#: lines of a crashed script's stderr shown as its failed check's detail
TAIL_LINES = 20
#: seconds an interrupted report gives a script to end after SIGTERM before it is killed
TERMINATE_WAIT = 10.0
#: scripts that read another's output in the report folder, and the script they wait for
#: (mom_1d_model reuses fig6_mom's MoM run, fig6_mom.npz, instead of running it again)
AFTER = {"mom_1d_model": "fig6_mom"}
#: most scripts at once by default (each script's own threads -- Dr.Jit's, BLAS's -- share the cores)
MAX_JOBS = 4


def validation_dir(scripts=None) -> Path:
    """The validation scripts' folder (``scripts``, or the package's own); UsageError when it holds
    none of the report's scripts."""
    here = Path(VALIDATION_DIR if scripts is None else scripts)
    missing = [f"{stem}.py" for _, names in SECTIONS for stem in names if not (here / f"{stem}.py").is_file()]
    if not here.is_dir() or len(missing) == sum(len(n) for _, n in SECTIONS):
        if scripts is not None:
            raise UsageError(f"--scripts {str(here)!r} holds none of the validation scripts (fig4_priest_germer.py, "
                             "...): give a folder like hyde_bsdf/validation/ of a hyde-bsdf checkout")
        raise UsageError(f"the package's validation scripts are missing from {str(here)!r} (an incomplete "
                         "install): reinstall hyde-bsdf, or give a folder of them with --scripts")
    return here.resolve()


#: the tag in a report's index.html by which a rerun knows the folder is a report's
GENERATOR = '<meta name="generator" content="hyde-bsdf validate">'


def _is_report(folder: Path) -> bool:
    try:
        with open(folder / "index.html", "rb") as fh:
            return GENERATOR.encode() in fh.read(4096)
    except OSError:
        return False


def check_report_dir(outdir, force: bool = False) -> Path:
    """Check before any work that ``outdir`` can take a report (UsageError otherwise).

    Refused: a regular file, the current folder or one above it, and -- unless ``force`` -- a
    folder that holds files and is not an earlier report (see the module docstring).
    """
    out = Path(outdir).resolve()
    here = Path.cwd().resolve()
    if out == here or out in here.parents:
        raise UsageError(f"--outdir {str(outdir)!r} is the current folder or one above it: give the report "
                         "a folder of its own (default out/report)")
    if out.exists() and not out.is_dir():
        raise UsageError(f"--outdir {str(outdir)!r} is a regular file, not a folder")
    others = sorted(p.name for p in out.iterdir() if not TEMP_NAME_RE.match(p.name)) if out.is_dir() else []
    if others and not force and not _is_report(out):
        shown = ", ".join(repr(f) for f in others[:3]) + (" ..." if len(others) > 3 else "")
        raise UsageError(f"--outdir {str(outdir)!r} is not a validation report and holds {len(others)} file(s) "
                         f"({shown}); give a new or empty folder, or pass --force to write the report beside them "
                         "(files of the report's names are replaced)")
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
    if total_memory() is not None:
        info["memory"] = format_bytes(total_memory())
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


def script_command(path: Path, outdir: Path, quick: bool, checks_json: Path) -> list:
    """The child's command line: the script itself, run by this interpreter, answering the
    protocol of ``hyde_bsdf/validation/_common.py`` (``--checks-json FILE``)."""
    cmd = [sys.executable, str(path), "-o", os.path.abspath(outdir), "--checks-json", str(checks_json)]
    return cmd + (["--quick"] if quick else [])


#: the thread pools of NumPy's BLAS, OpenMP and Dr.Jit: with several scripts at once each child gets its
#: share of the cores (a user's own setting is kept).  Dr.Jit reads no variable of its own: the scripts'
#: protocol (``hyde_bsdf/validation/_common.py``) sets its pool from :data:`DRJIT_THREADS`.  Measured
#: (capture_camera --quick at load 8): 24 CPU s with Dr.Jit's default pool of one thread per core, 15 with one
#: thread -- the validation's kernels are small, and idle workers spin on cores other scripts need
DRJIT_THREADS = "HYDE_DRJIT_THREADS"
THREAD_VARIABLES = ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", DRJIT_THREADS)


def _child_env(jobs: int = 1) -> dict:
    """The report's environment; when this package runs from a source tree, that tree goes first
    on the child's PYTHONPATH, so the scripts import the same ``hyde_bsdf`` as the report.  With
    ``jobs`` scripts at once, BLAS, OpenMP and Dr.Jit get ``cores // jobs`` threads each (a spinning
    thread pool on a core another script needs slows both)."""
    env = dict(os.environ)
    root = Path(__file__).resolve().parents[3]
    if (root / "pyproject.toml").is_file():
        env["PYTHONPATH"] = os.pathsep.join([str(root)] + [p for p in [env.get("PYTHONPATH")] if p])
    if jobs > 1:
        for name in THREAD_VARIABLES:
            env.setdefault(name, str(max(1, (os.cpu_count() or 1) // jobs)))
    return env


class _Child:
    """One script running as a child process, its stderr in a file and the protocol's file in a
    private temporary folder; :meth:`result` reads them once it has ended."""

    def __init__(self, path: Path, outdir: Path, quick: bool, jobs: int = 1):
        self.path, self.outdir, self.t0 = path, Path(outdir), time.perf_counter()
        self.limit, self.limit_name = wait_limit("script")      # a script that hangs is killed there
        # inside the report's temporary folder: a killed run (SIGKILL from hyde-bsdf's waiting process) leaves nothing
        self.work = tempfile.TemporaryDirectory(prefix=".work-", dir=self.outdir)
        self.stderr = tempfile.TemporaryFile(dir=self.work.name)
        self.checks_json = Path(self.work.name) / f"{path.stem}.checks.json"
        try:
            self.proc = subprocess.Popen(script_command(path, outdir, quick, self.checks_json),
                                         stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL, stderr=self.stderr,
                                         env=_child_env(jobs))
        except BaseException:
            self.close()
            raise

    def close(self):
        self.stderr.close()
        self.work.cleanup()

    def check_limit(self):
        """Kill the child once it has run longer than the script limit: one failed check, never a hang."""
        if self.proc.poll() is None and time.perf_counter() - self.t0 > self.limit:
            self.proc.kill()
            self.proc.wait()
            self.stderr.write(f"\ntimed out after {self.limit:g} s ({self.limit_name}): killed\n".encode())

    def stop(self):
        """Terminate the child (SIGTERM, then SIGKILL after :data:`TERMINATE_WAIT` s) and reap it."""
        if self.proc.poll() is None:
            self.proc.terminate()
            try:
                self.proc.wait(TERMINATE_WAIT)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait()
        self.close()

    def result(self) -> dict:
        """The ended child's checks, wall and CPU seconds, docstring and figures (see
        :func:`_run_script`); KeyboardInterrupt when it died of SIGINT (Ctrl-C reached it first)."""
        status = self.proc.returncode
        seconds = time.perf_counter() - self.t0
        if status == -signal.SIGINT:
            self.close()
            raise KeyboardInterrupt
        got = _read_checks(self.checks_json) if status == 0 else None
        detail = _tail(self.stderr) if got is None else ""
        self.close()
        if got is not None:
            checks, doc, names, cpu = got
            figures = [self.outdir / n for n in dict.fromkeys(names) if (self.outdir / n).is_file()]
            return dict(checks=checks, seconds=seconds, doc=doc, figures=figures, cpu=cpu)
        last = (detail.splitlines() or [""])[-1].strip()
        last = last if len(last) <= 300 else last[:297] + "..."
        value = f"exit status {status}" + (f": {last}" if last else " (no output on stderr)")
        if status == 0:
            value += ", and no checks came back (does its __main__ block call hyde_bsdf/validation/_common.py's cli?)"
        return dict(checks=[dict(name=f"{self.path.stem}: ran", value=value, tolerance="no error", passed=False,
                                 detail=detail)], seconds=seconds, doc="", figures=[], cpu=None)


def _tail(stderr, lines: int = TAIL_LINES) -> str:
    """The last ``lines`` lines of the open file ``stderr`` (only its last 64 KiB are read)."""
    size = stderr.seek(0, os.SEEK_END)
    stderr.seek(max(0, size - 65536))
    text = stderr.read().decode("utf-8", errors="replace")
    return "\n".join(text.rstrip().splitlines()[-lines:])


def _read_checks(path: Path):
    """(checks, doc, figure names, CPU seconds) from a child's ``--checks-json`` file; None when it
    is absent or malformed.  Figures: the PNG files the script saved in its output folder."""
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
        checks = [dict(c) for c in data["checks"]]
        if not all("name" in c and "passed" in c for c in checks):
            return None
        names = [Path(str(f)).name for f in data.get("figures", [])]
        cpu = data.get("cpu_seconds")
        return ([dict(c, passed=bool(c["passed"])) for c in checks], str(data.get("doc") or ""), names,
                float(cpu) if isinstance(cpu, (int, float)) else None)
    except (OSError, ValueError, KeyError, TypeError):
        return None


def _missing(path: Path) -> dict:
    return dict(checks=[dict(name=f"{path.stem}: script present", value="missing", tolerance="present",
                             passed=False)], seconds=0.0, doc="", figures=[], cpu=None)


def _run_all(paths: list, outdir: Path, quick: bool, jobs: int = 1, progress=None) -> dict:
    """Run the scripts ``paths``, ``jobs`` at a time, in their order (a script of :data:`AFTER`
    waits for the one it reads); {stem: result} (see :func:`_run_script`).  On any interruption
    (Ctrl-C, SIGTERM as :class:`~hyde_bsdf.app.signals.Terminated`, a child that died of SIGINT)
    every running child is terminated and reaped before the interruption goes on."""
    pending, running, results = list(paths), [], {}
    stems = {p.stem for p in paths}
    try:
        while pending or running:
            ready = [p for p in pending if AFTER.get(p.stem) not in stems or AFTER[p.stem] in results]
            while ready and len(running) < jobs:
                path = ready.pop(0)
                pending.remove(path)
                if progress:
                    progress(f"{len(paths) - len(pending)}/{len(paths)} {path.stem} ...")
                if not path.is_file():
                    results[path.stem] = _missing(path)
                    continue
                running.append(_Child(path, outdir, quick, jobs))
            if not running:
                continue
            for child in running:
                child.check_limit()
            ended = [c for c in running if c.proc.poll() is not None]
            if not ended:
                time.sleep(0.05)
                continue
            for child in ended:
                running.remove(child)
                got = results[child.path.stem] = child.result()
                if progress:
                    bad = sum(not c["passed"] for c in got["checks"])
                    cpu = "" if got["cpu"] is None else f" ({got['cpu']:.1f} CPU s)"
                    progress(f"   {child.path.stem}: {got['seconds']:.1f} s{cpu}, {len(got['checks'])} checks, "
                             f"{bad} failed")
    except BaseException:
        for child in running:
            child.stop()
        raise
    return results


def _run_script(path: Path, outdir: Path, quick: bool):
    """Run one script as a child process: (checks, seconds, docstring).  A missing script, or one
    that ends without its checks (a crash, a kill), is one failed check; the last lines of its
    stderr are that check's detail.  The protocol's files live in a private temporary folder."""
    got = _run_all([path], outdir, quick)[path.stem]
    return got["checks"], got["seconds"], got["doc"]


def _fmt(v):
    if isinstance(v, float):
        return f"{v:.4g}"
    return html.escape(str(v))


def default_jobs() -> int:
    """Scripts at once by default: one per core, at most :data:`MAX_JOBS`."""
    return max(1, min(MAX_JOBS, os.cpu_count() or 1))


def build_report(outdir, quick=False, progress=True, force=False, scripts=None, jobs=None):
    """Run all scripts into ``outdir``, ``jobs`` at a time (default :func:`default_jobs`); return
    (all_passed, rows, seconds).

    The report is built in a fresh folder and moved into ``outdir`` only once complete (see the
    module docstring); UsageError before any work for an unusable ``outdir`` (a folder that is not
    a report's, unless ``force``), no scripts (in ``scripts``, default the package's
    ``hyde_bsdf/validation/``) or ``jobs`` below 1.
    """
    jobs = default_jobs() if jobs is None else jobs
    if not isinstance(jobs, int) or isinstance(jobs, bool) or jobs < 1:
        raise UsageError(f"jobs must be a whole number >= 1, got {jobs!r}")
    final = check_report_dir(outdir, force)
    vdir = validation_dir(scripts)
    check_not_input([final], [vdir], "--outdir")          # the report is not the scripts' folder
    with OutputLock([final], "--outdir"), atomic_folder(final) as out:     # one report run per folder
        previous = _previous_cpu(final / "times.csv", quick) or _previous_cpu(MEASURED_TIMES, quick)
        return _build(out, vdir, quick, as_callback(progress, "[validate]"), jobs, previous)


#: the ``times.csv`` of a measured report (quick and full rows), shipped with the package: the order a first report
#: starts the scripts in (the longest first; a rerun reads its own folder's)
MEASURED_TIMES = Path(__file__).resolve().parents[2] / "data" / "validation_times.csv"


def _previous_cpu(path: Path, quick: bool) -> dict:
    """{script: CPU seconds} of the report of the same mode in the ``times.csv`` at ``path``; empty when there is
    none or it cannot be read."""
    try:
        with open(path, newline="", encoding="utf-8") as fh:
            return {r["script"]: float(r["cpu_seconds"]) for r in csv.DictReader(fh)
                    if r["mode"] == ("quick" if quick else "full") and r["cpu_seconds"]}
    except (OSError, KeyError, ValueError, TypeError):
        return {}


def _build(out: Path, vdir: Path, quick: bool, progress, jobs: int, previous: dict):
    info = machine_info()
    t_start = time.perf_counter()
    stems = [s for _, names in SECTIONS for s in names]
    # the longest scripts of the earlier report first (new ones before them): the cores stay busy
    # to the end instead of one long script running alone
    order = sorted(stems, key=lambda stem: -previous.get(stem, math.inf))
    results = _run_all([vdir / f"{stem}.py" for stem in order], out, quick, jobs, progress)
    total = time.perf_counter() - t_start
    rows, sections = [], []
    for title, names in SECTIONS:
        entries = []
        for stem in names:
            got = results[stem]
            for c in got["checks"]:
                rows.append(dict(script=stem, **{k: c.get(k, "") for k in ("name", "value", "tolerance", "passed")}))
            entries.append((stem, got))
        sections.append((title, entries))
    cpu = [results[s]["cpu"] for s in stems if results[s]["cpu"] is not None]
    info["report run time"] = (f"{total:.0f} s ({'quick' if quick else 'full'} mode, {jobs} script(s) at once; "
                               f"the scripts' CPU time {sum(cpu):.0f} s)")
    all_passed = all(r["passed"] for r in rows)
    _write_html(out, info, sections, rows, all_passed, quick)
    with atomic_open(out / "checks.csv", "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=["script", "name", "value", "tolerance", "passed"])
        w.writeheader()
        w.writerows(rows)
    with atomic_open(out / "times.csv", "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["script", "mode", "seconds", "cpu_seconds", "jobs"])
        w.writerows([stem, "quick" if quick else "full", f"{results[stem]['seconds']:.2f}",
                     "" if results[stem]["cpu"] is None else f"{results[stem]['cpu']:.2f}", jobs] for stem in stems)
    return all_passed, rows, total


def _write_html(out, info, sections, rows, all_passed, quick):
    n_fail = sum(not r["passed"] for r in rows)
    parts = [
        f"<!doctype html><html><head><meta charset='utf-8'>{GENERATOR}<title>hyde-bsdf validation report</title>",
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
        for stem, got in entries:
            cpu = "" if got["cpu"] is None else f", {got['cpu']:.1f} CPU s"
            parts.append(f"<h3>{stem} <small>({got['seconds']:.1f} s{cpu})</small></h3>")
            if got["doc"]:
                parts.append(f"<pre>{html.escape(got['doc'])}</pre>")
            for c in got["checks"]:
                if c.get("detail"):
                    parts.append(f"<pre>{html.escape(c['detail'])}</pre>")
            for fig in got["figures"]:
                parts.append(f"<img src='{html.escape(fig.name)}' alt='{html.escape(fig.stem)}'>")
    parts.append("</body></html>")
    with atomic_open(out / "index.html", "w", encoding="utf-8") as f:
        f.write("\n".join(parts))


def build_parser() -> Parser:
    ap = Parser(prog="hyde-bsdf validate", description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    writes(ap.add_argument("-o", "--outdir", default="out/report", help="report folder (default out/report)"))
    ap.add_argument("--quick", action="store_true", help="small sweeps (about 260 CPU s: 6 minutes measured on 2 cores at load 7; docs/validation.md)")
    reads(ap.add_argument("--scripts", metavar="DIR", default=None,
                          help="folder of the validation scripts (default: the package's own, hyde_bsdf/validation/)"),
          "folder")
    ap.add_argument("--jobs", "-j", type=positive_int, default=None, metavar="N",
                    help=f"scripts run at once (default: one per core, at most {MAX_JOBS}; 1 runs them one after "
                         "another)")
    ap.add_argument("--force", action="store_true",
                    help="write into a folder that is not an earlier report; its files are kept, except "
                         "those of the report's names (index.html, checks.csv, times.csv, the figures), which are replaced")
    quiet_option(ap)
    return ap


def cli_main(argv=None) -> int:
    """``hyde-bsdf validate``: 0 when every check passes, 1 otherwise; user errors raise UsageError."""
    a = build_parser().parse_args(argv)
    ok, rows, seconds = build_report(a.outdir, quick=a.quick, force=a.force, progress=not a.quiet,
                                     scripts=a.scripts, jobs=a.jobs)
    n_fail = sum(not r["passed"] for r in rows)
    print(f"{len(rows) - n_fail} of {len(rows)} checks pass in {seconds:.0f} s; report: {Path(a.outdir) / 'index.html'}")
    for r in rows:
        if not r["passed"]:
            print(f"  FAIL [{r['script']}] {r['name']}: {r['value']} (tolerance {r['tolerance']})")
    return 0 if ok else 1
