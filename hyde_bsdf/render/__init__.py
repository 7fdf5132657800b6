"""Rendering with the plugin: polarized renders, Stokes I/O and the demo.

``renderer`` (:func:`render_stokes`, the ``hyde-bsdf render`` command), ``stokes_io`` (Stokes
EXR files and the DoLP/AoLP/DoCP pictures), ``demo`` (``hyde-bsdf demo``).
Inverse rendering, which uses the renderer, is its own subpackage, :mod:`hyde_bsdf.inverse`.

May import: ``hyde_bsdf.model``, ``hyde_bsdf.mitsuba``, ``hyde_bsdf.fit``.  Only ``hyde_bsdf.inverse`` and
``hyde_bsdf.report`` import this subpackage.
"""
from hyde_bsdf.render.renderer import (DEFAULT_VARIANT, cli_main, load_scene, prepare_variant,
                                       render_stokes, rotate_stokes, sensor_to_paper_rotation)

__all__ = ["DEFAULT_VARIANT", "prepare_variant", "load_scene", "render_stokes",
           "sensor_to_paper_rotation", "rotate_stokes", "cli_main"]
