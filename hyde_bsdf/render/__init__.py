"""Rendering with the plugin: polarized renders, Stokes I/O, the demo and inverse rendering.

``renderer`` (:func:`render_stokes`, the ``hyde-bsdf render`` command), ``stokes_io`` (Stokes
EXR files and the DoLP/AoLP/DoCP pictures), ``demo`` (``hyde-bsdf demo``), ``inverse``
(differentiable inverse rendering, ``hyde-bsdf invert``).

May import: ``hyde_bsdf.model``, ``hyde_bsdf.mitsuba``, ``hyde_bsdf.fit``.  Nothing below it
imports this subpackage.
"""
from hyde_bsdf.render.renderer import (DEFAULT_VARIANT, cli_main, load_scene, prepare_variant,
                                       render_stokes, rotate_stokes, sensor_to_paper_rotation)

__all__ = ["DEFAULT_VARIANT", "prepare_variant", "load_scene", "render_stokes",
           "sensor_to_paper_rotation", "rotate_stokes", "cli_main"]
