"""The validation report (``hyde-bsdf validate``): runs the scripts of the checkout's
``validation/`` folder and writes one HTML page with every check and figure.

``build`` (:func:`build_report`, the command).  May import everything else in ``hyde_bsdf``;
nothing imports it.
"""
from hyde_bsdf.report.build import SECTIONS, build_report, cli_main

__all__ = ["SECTIONS", "build_report", "cli_main"]
