"""The validation report (``hyde-bsdf validate``): runs the scripts of the checkout's
``validation/`` folder and writes one HTML page with every check and figure.

It is part of the application (:mod:`hyde_bsdf.app`): it may import anything in ``hyde_bsdf``,
and nothing in the library imports it.  The rule for the validation scripts: they are not part
of the installed package, and the package never imports them -- the report runs each one as a
child process (``python SCRIPT.py ... --checks-json FILE``, the protocol of
``validation/_common.py``) and reads its checks back, so one script's Dr.Jit/Mitsuba state or
memory cannot reach the next.  The scripts come from ``validation/`` of the source checkout the
package runs from, or from ``--scripts DIR`` (:func:`~hyde_bsdf.app.report.build.validation_dir`);
with neither (an installed wheel) ``validate`` refuses in one line, exit 2.  The scripts may import
the library and :mod:`hyde_bsdf.app`, never the other way round (``tests/test_report.py`` checks
that no module of the package loads a file as code or changes ``sys.path``).

``build`` (:func:`build_report`, the command).
"""
from hyde_bsdf.app.report.build import SECTIONS, build_report, cli_main

__all__ = ["SECTIONS", "build_report", "cli_main"]
