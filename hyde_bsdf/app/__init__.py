"""The top layer: the ``hyde-bsdf`` command line, its plots and pictures, the demo and the report.

``cli``       the dispatcher, ``hyde-bsdf COMMAND``; errors become one line and an exit code here
``args``      what every sub-command's parser shares
``fit``       ``hyde-bsdf fit`` (Mueller CSV or ``.pbsdf`` table)
``export``    ``hyde-bsdf export``
``render``    ``hyde-bsdf render``
``demo``      ``hyde-bsdf demo``
``invert``    ``hyde-bsdf invert``
``report``    ``hyde-bsdf validate`` (runs the ``hyde_bsdf.validation`` scripts, each as a child process)
``plots``     fit and inversion plots (matplotlib)
``pictures``  PNG charts of a Stokes image (matplotlib)
"""
