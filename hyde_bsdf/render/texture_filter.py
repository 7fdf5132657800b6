"""Switching a loaded scene's bitmap texture to nearest-neighbour lookup.

Mitsuba's ``bitmap`` filters bilinearly by default: a pixel then blends the four texels around it,
while per-texel fitting (:func:`hyde_bsdf.inverse.invert_maps`) and its standard errors assume that
a pixel inside a texel depends on that texel only.  A texture's ``filter_type`` cannot be changed
through ``mi.traverse``, so :func:`bitmap_to_nearest` builds a nearest bitmap with the same data and
puts it into the BSDF in place of the old one (the ``hyde`` plugin's ``replace_texture``).
"""
from __future__ import annotations

import re

import numpy as np

__all__ = ["bitmap_to_nearest"]


def bitmap_to_nearest(scene, params, key: str) -> bool:
    """Replace the bitmap texture whose data is ``params[key]`` (shape (rows, cols, C)) by a nearest
    one holding the same data, in the BSDF that owns it.  True when replaced; False when no BSDF of
    the scene's shapes can take it (only BSDFs with a ``replace_texture`` method can: the ``hyde``
    plugin) or when the new texture does not return the old one's values at the texel centres (a
    ``to_uv`` transform or other settings this copy would lose).  ``params`` is stale afterwards:
    call ``mi.traverse(scene)`` again."""
    import drjit as dr
    import mitsuba as mi

    node = params.properties[key][2]
    if not isinstance(node, mi.Texture):
        return False
    owner = _owner(scene, node)
    if owner is None:
        return False
    bsdf, name = owner
    data = np.asarray(params[key], np.float32)
    if data.ndim != 3:
        return False
    raw = re.search(r"raw\s*=\s*0", str(node)) is None
    new = mi.load_dict({"type": "bitmap", "bitmap": mi.Bitmap(data), "raw": raw, "filter_type": "nearest"})
    rows, cols = data.shape[:2]
    r, c = np.divmod(np.arange(rows * cols), cols)
    si = dr.zeros(mi.SurfaceInteraction3f, rows * cols)
    si.uv = mi.Point2f(((c + 0.5) / cols).astype(np.float32), ((r + 0.5) / rows).astype(np.float32))
    before = np.asarray(node.eval_1(si), np.float64)
    after = np.asarray(new.eval_1(si), np.float64)
    if not np.allclose(before, after, rtol=1e-5, atol=1e-7):
        return False
    bsdf.replace_texture(name, new)
    return True


def _owner(scene, node):
    """(bsdf, traverse name) of the shape BSDF holding texture ``node``, or None."""
    for shape in scene.shapes():
        bsdf = shape.bsdf()
        if bsdf is None or not hasattr(bsdf, "replace_texture"):
            continue
        for name, tex in bsdf._textures().items():
            if tex is node:
                return bsdf, name
    return None
