"""Shared test set-up: a per-session DHR cache folder (tests never touch ~/.cache) and the
Hypothesis settings profile.

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
import tempfile

# Set before any hyde_bsdf import builds or reads a DHR table.
os.environ.setdefault("HYDE_BSDF_CACHE", os.path.join(tempfile.gettempdir(), "hyde-bsdf-test-cache"))
os.environ.setdefault("MPLBACKEND", "Agg")

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
