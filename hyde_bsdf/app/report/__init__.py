"""The validation report (``hyde-bsdf validate``): runs the validation scripts
(:mod:`hyde_bsdf.validation`) and writes one HTML page with every check and figure.

It is part of the application (:mod:`hyde_bsdf.app`): it may import anything in ``hyde_bsdf``,
and nothing in the library imports it.  The rule for the validation scripts: they ship with the
package (the top layer, :mod:`hyde_bsdf.validation`), and nothing imports them -- the report runs
each one as a child process (``python SCRIPT.py ... --checks-json FILE``, the protocol of
``hyde_bsdf/validation/_common.py``) and reads its checks back, so one script's Dr.Jit/Mitsuba
state or memory cannot reach the next.  The scripts come from the package, or from ``--scripts
DIR`` (:func:`~hyde_bsdf.app.report.build.validation_dir`).  The scripts may import the library
and :mod:`hyde_bsdf.app`, never the other way round (``tests/test_layers.py``; and
``tests/test_report.py`` checks that no module of the package loads a file as code or changes
``sys.path``).

``build`` (:func:`build_report`, the command).
"""
from hyde_bsdf.app.report.build import SECTIONS, build_report, cli_main

__all__ = ["SECTIONS", "build_report", "cli_main"]
