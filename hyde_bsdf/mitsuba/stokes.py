"""The facet Mueller matrix (paper Eq. 11) rotated from the facet's s/p bases into Mitsuba's Stokes bases.

Mitsuba's ``mi.mueller.rotate_mueller_basis(M, in_fwd, in_cur, in_tgt, out_fwd, out_cur, out_tgt)``
returns ``R_out @ M @ R_in^T`` with the Stokes rotator ``R(theta) = [[1, 0, 0, 0], [0, c, s, 0],
[0, -s, c, 0], [0, 0, 0, 1]]``, (c, s) = (cos 2 theta, sin 2 theta), theta the angle from the current
to the target reference axis, signed by the propagation direction (``mueller.h``:
``rotate_stokes_basis``).  The facet matrix has only 8 nonzero entries (a, b, c, s below), so the
two 4 x 4 products reduce to the 14 nonzero entries written out in :func:`rotated_facet_mueller`:
the same matrix (to float32 rounding, ~4e-7 absolute for unit entries) at a fraction of the traced
operations (the two generic products of a spectral Mueller matrix are ~900 operations on 4-wavelength
arrays per call, traced on the host at every render).
"""
from __future__ import annotations

import drjit as dr
import mitsuba as mi

__all__ = ["stokes_rotation", "rotated_facet_mueller"]


def stokes_rotation(forward, current, target):
    """(cos 2 theta, sin 2 theta) of the rotation of a Stokes reference axis about ``forward``.

    ``current`` and ``target`` are unit axes perpendicular to ``forward``; theta is the angle
    from ``current`` to ``target``, positive counter-clockwise about ``forward`` (Mitsuba's
    ``rotate_stokes_basis``).  cos theta = current . target, sin theta = forward . (current x
    target): double-angle formulas, no trigonometric function.
    """
    cos_t = dr.dot(current, target)
    sin_t = dr.dot(forward, dr.cross(current, target))
    return cos_t * cos_t - sin_t * sin_t, 2.0 * sin_t * cos_t


def rotated_facet_mueller(a, b, c, s, rot_in, rot_out, spec, diff):
    """``spec`` R_out F R_in^T + ``diff`` a e00 as a ``mi.Spectrum`` (a Mueller matrix).

    ``a, b, c, s``: the facet Fresnel entries (:func:`hyde_bsdf.mitsuba.optics.fresnel_mueller_entries`,
    F = [[a, b, 0, 0], [b, a, 0, 0], [0, 0, c, -s], [0, 0, s, c]] in the facet's s/p bases);
    ``rot_in`` / ``rot_out``: (cos 2 theta, sin 2 theta) of :func:`stokes_rotation` on the incident
    and outgoing side; ``spec`` scales the specular matrix, ``diff`` adds the unpolarized diffuse
    term a * diff to the [0, 0] element only (paper Eq. 17).  The matrix is assembled from its
    entries (one constructor call): an operation on a whole spectral Mueller matrix (a select, a
    product) costs ~50-200 us of host time each in Python, against ~3 us per entry.
    """
    ci, si = rot_in
    co, so = rot_out
    a_s, b_s, c_s, s_s = a * spec, b * spec, c * spec, s * spec
    m00 = a_s if isinstance(diff, float) and diff == 0.0 else a_s + a * diff
    cc, ss, sc, cs = co * ci, so * si, so * ci, co * si
    zero = dr.zeros(type(a_s), dr.width(a_s))      # as wide as the other entries (a literal: no memory)
    return mi.Spectrum(m00, ci * b_s, -si * b_s, zero,
                       co * b_s, cc * a_s + ss * c_s, sc * c_s - cs * a_s, -so * s_s,
                       -so * b_s, cs * c_s - sc * a_s, ss * a_s + cc * c_s, -co * s_s,
                       zero, si * s_s, ci * s_s, c_s)
