"""The validation scripts: one per validation result, each writing a PNG and a CSV.

The top layer of the package: a script may import anything in ``hyde_bsdf`` (the application's
:mod:`hyde_bsdf.app` included) and nothing imports a script -- ``hyde-bsdf validate`` runs each one
as a child process (``python .../validation/STEM.py -o OUTDIR [--quick] --checks-json FILE``, the
protocol of :mod:`hyde_bsdf.validation._common`).  They ship with the package, so the report runs
from an installed wheel as from a checkout.  Each also runs on its own:
``python -m hyde_bsdf.validation.STEM [-o OUTDIR] [--quick]``.
"""
