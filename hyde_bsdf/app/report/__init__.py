"""The validation report (``hyde-bsdf validate``): runs the scripts of the checkout's
``validation/`` folder and writes one HTML page with every check and figure.

It is part of the application (:mod:`hyde_bsdf.app`): it may import anything in ``hyde_bsdf``,
and nothing in the library imports it.  The rule for the validation scripts: they are not part
of the installed package; the report loads them from ``validation/`` of the source checkout it
runs in (:func:`~hyde_bsdf.app.report.build.validation_dir`), and ``validate`` refuses in one
line, exit 2, when there is none (an installed wheel) -- the scripts may import the library and
:mod:`hyde_bsdf.app`, never the other way round.

``build`` (:func:`build_report`, the command).
"""
from hyde_bsdf.app.report.build import SECTIONS, build_report, cli_main

__all__ = ["SECTIONS", "build_report", "cli_main"]
