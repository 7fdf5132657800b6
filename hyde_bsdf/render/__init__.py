"""Rendering with the plugin: polarized renders and the polarization quantities of a Stokes image.

``renderer`` (:func:`render_stokes`), ``polarization`` (intensity, DoLP, AoLP, DoCP).  Stokes EXR
files are :mod:`hyde_bsdf.io.stokes_exr`; the ``hyde-bsdf render`` and ``demo`` commands and the
PNG charts are in :mod:`hyde_bsdf.app`.  Inverse rendering, which uses the renderer, is its own
subpackage, :mod:`hyde_bsdf.inverse`.
"""
from hyde_bsdf.render.renderer import (DEFAULT_VARIANT, load_scene, prepare_variant, render_stokes, rotate_stokes,
                                       sensor_to_paper_rotation)

__all__ = ["DEFAULT_VARIANT", "prepare_variant", "load_scene", "render_stokes",
           "sensor_to_paper_rotation", "rotate_stokes"]
