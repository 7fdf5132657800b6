"""Shared test set-up: the Hypothesis settings profile; SIGINT as from a terminal (see below).

Hypothesis profiles (``HYPOTHESIS_PROFILE``):

* ``ci`` (the default, used by ``./run.sh test`` and CI): derandomized, i.e. the same examples
  on every run from a fixed seed, no example database, no deadline.  Every failure found so far
  is pinned as an ``@example`` in its test, so a fixed run still replays it.  A submission can
  never be rejected by a case that a previous run did not draw.
* ``thorough``: random seeds and 10x the examples (``max_examples`` of each test times
  :data:`THOROUGH_FACTOR`), with the example database on, for exploring:
  ``HYPOTHESIS_PROFILE=thorough ./run.sh test -k properties``.  Pin what it finds as an
  ``@example``.

Tests set their own count with ``max_examples=examples(N)``: N in ``ci``, 10 N in ``thorough``.
"""
import os
import signal

os.environ.setdefault("MPLBACKEND", "Agg")
# A suite started in the background of a shell without job control (`( ./run.sh test & )`) inherits
# SIGINT ignored, under nohup SIGHUP too, and so would every command the signal tests start: their
# Ctrl-C and hang-up rows would wait for the watchdog.  A handler (unlike an ignore) is reset to the
# default at exec, so the children get the signals as from a terminal, however the suite was started
# (the suite itself still shrugs off a hang-up it was told to ignore).
if signal.getsignal(signal.SIGINT) is signal.SIG_IGN:
    signal.signal(signal.SIGINT, signal.default_int_handler)
if signal.getsignal(signal.SIGHUP) is signal.SIG_IGN:
    signal.signal(signal.SIGHUP, lambda signum, frame: None)

import pytest  # noqa: E402
from hypothesis import HealthCheck, settings  # noqa: E402

#: multiplier of each test's example count under the ``thorough`` profile
THOROUGH_FACTOR = 10
_SLOW_OK = [HealthCheck.too_slow, HealthCheck.data_too_large]

settings.register_profile("ci", derandomize=True, database=None, deadline=None, print_blob=True,
                          suppress_health_check=_SLOW_OK)
settings.register_profile("thorough", derandomize=False, deadline=None, print_blob=True,
                          suppress_health_check=_SLOW_OK)
PROFILE = os.environ.get("HYPOTHESIS_PROFILE", "ci")
if PROFILE not in ("ci", "thorough"):
    raise RuntimeError(f"HYPOTHESIS_PROFILE={PROFILE!r}: expected 'ci' (default) or 'thorough'")
settings.load_profile(PROFILE)


def examples(n: int) -> int:
    """A test's example count: ``n`` in the ``ci`` profile, ``THOROUGH_FACTOR * n`` in ``thorough``."""
    return n * (THOROUGH_FACTOR if PROFILE == "thorough" else 1)


#: the longest tests, started first so that the other worker runs the rest meanwhile (pytest-xdist
#: hands tests out in collection order)
LONGEST_FIRST = ("test_report.py::test_quick_report_of_each_script", "test_docs.py::test_code_blocks_run")


def pytest_collection_modifyitems(config, items):
    items.sort(key=lambda item: 0 if LONGEST_FIRST[0] in item.nodeid else 1 if LONGEST_FIRST[1] in item.nodeid else 2)


# ---------------------------------------------------------------------------------------------
# waits that survive load (issue 24, item 7)
#
# No test asserts a wall-clock limit.  A test that must wait for another process waits for an
# event (a line on its output, its exit); the time it allows before calling the process hung is
# ``scaled(seconds)``: ``seconds`` is what a quiet 2-core machine needs with a wide margin, times
# SLOWDOWN, measured once at the start of the session: the larger of (a) the median time of a
# fixed pure-Python workload now over its best time on a quiet machine and (b) the load average
# per core.  A machine loaded at 4x its cores gets about 4x the time, a quiet one 1x.

import time  # noqa: E402

#: best time (s) of :func:`_workload` on the development machine (2 cores): the min of 60 runs,
#: 0.0175 s, measured while the machine was loaded at ~6x its cores (the best run is an
#: uncontended one; the median was 0.077 s, 4.4x, with a load average of 12.8 on 2 cores)
WORKLOAD_REFERENCE_S = 0.0175


def _workload() -> float:
    t0 = time.perf_counter()
    s = 0
    for i in range(200_000):
        s += i * i % 7
    return time.perf_counter() - t0


def _calibrate() -> float:
    runs = sorted(_workload() for _ in range(5))
    speed = runs[len(runs) // 2] / WORKLOAD_REFERENCE_S
    try:
        load = os.getloadavg()[0] / max(1, os.cpu_count() or 1)
    except OSError:
        load = 1.0
    return max(1.0, speed, load)


#: how much slower than a quiet machine this session runs (>= 1)
SLOWDOWN = _calibrate()


def scaled(seconds: float) -> float:
    """A hang guard: ``seconds`` on a quiet machine, stretched by :data:`SLOWDOWN`."""
    return seconds * SLOWDOWN


def pytest_report_header(config):
    return f"hang guards scaled by SLOWDOWN = {SLOWDOWN:.2f} (load and a calibration workload)"


@pytest.fixture(scope="module")
def map_variant():
    """The per-texel maps' Mitsuba variant for a test module, the previous variant restored after it."""
    import mitsuba as mi

    from hyde_bsdf import inverse as inv

    previous = mi.variant()
    inv.prepare(inv.observations.MAP_VARIANT)
    yield
    if previous is not None and previous != mi.variant():
        mi.set_variant(previous)


def library_modules(root=None) -> list:
    """Every ``.py`` file of the package that the code rules cover (function length, error types,
    range literals, stderr): all of ``hyde_bsdf/`` but the validation scripts in
    ``hyde_bsdf/validation/`` -- programs run by ``hyde-bsdf validate``, which those rules did not
    cover before they moved into the package (tests/test_layers.py covers them: the top layer)."""
    from pathlib import Path

    root = Path(root) if root is not None else Path(__file__).resolve().parent.parent / "hyde_bsdf"
    return sorted(p for p in root.rglob("*.py") if p.relative_to(root).parts[0] != "validation")


def mitsuba_with_hyde(variant: str):
    """Mitsuba set to ``variant`` (no fallback to another) with the ``hyde`` plugin registered in it:
    the plugin tests' one set-up.  Returns the ``mitsuba`` module."""
    import mitsuba as mi

    import hyde_bsdf
    from hyde_bsdf.mitsuba.variants import set_variant

    set_variant(variant, fallback=False)
    hyde_bsdf.register(variant)
    return mi


def docstring_ids(tree) -> set:
    """``id()`` of every docstring constant of a parsed module (its own, its classes' and functions'):
    the code-rule tests skip prose."""
    import ast

    out = set()
    for node in ast.walk(tree):
        if isinstance(node, (ast.Module, ast.ClassDef, ast.FunctionDef, ast.AsyncFunctionDef)) and node.body:
            first = node.body[0]
            if isinstance(first, ast.Expr) and isinstance(first.value, ast.Constant):
                out.add(id(first.value))
    return out


def textured_plane_scene(folder, target="0, 0, 0", size=16) -> str:
    """A polarized scene file in ``folder``: a ``hyde`` plane whose ``alpha`` is a 2 x 2 texture (``a.exr``,
    0.3, written here), seen from (0, -3, 3) looking at ``target`` by a ``size`` x ``size`` luminance
    film, under a point light.  The inverse-rendering CLI tests' sample; returns the scene's path."""
    from pathlib import Path

    import mitsuba as mi
    import numpy as np

    folder = Path(folder)
    mi.Bitmap(np.full((2, 2, 1), 0.3, np.float32)).write(str(folder / "a.exr"))
    (folder / "s.xml").write_text(f"""<scene version="3.0.0">
  <integrator type="stokes"><integrator type="path"><integer name="max_depth" value="2"/></integrator></integrator>
  <sensor type="perspective"><float name="fov" value="40"/>
    <transform name="to_world"><lookat origin="0, -3, 3" target="{target}" up="0, 0, 1"/></transform>
    <film type="hdrfilm"><integer name="width" value="{size}"/><integer name="height" value="{size}"/>
      <string name="pixel_format" value="luminance"/><rfilter type="box"/></film></sensor>
  <shape type="rectangle" id="plane"><bsdf type="hyde"><texture type="bitmap" name="alpha">
    <string name="filename" value="{folder / 'a.exr'}"/><boolean name="raw" value="true"/>
    <string name="filter_type" value="nearest"/></texture><float name="eta" value="1.5"/></bsdf></shape>
  <emitter type="point"><point name="position" x="0" y="3" z="3"/><float name="intensity" value="20"/></emitter>
</scene>""")
    return str(folder / "s.xml")
