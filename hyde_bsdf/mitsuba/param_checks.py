"""Checks of the ``hyde`` plugin's parameters, on the values Mitsuba will evaluate.

A texture's traversable data is not always what its ``eval`` returns: an 8-bit PNG bitmap
stores 0-255 in non-spectral variants (``eval`` divides by 255 and, unless ``raw``, converts
sRGB to linear), spectral variants store spectral-upsampling coefficients, and mono variants
take the luminance of RGB texels at evaluation.  So every check here reads the values through
the texture's own ``eval`` / ``eval_1``:

* constant (spatially uniform) textures: at 48 wavelengths 360-830 nm (spectral), the three
  channels (RGB) or the one value (mono), :func:`probe`;
* bitmaps: at the centre of every texel (the inverse of ``to_uv`` applied), every channel, at
  the same 48 wavelengths, :func:`texel_values`; one vectorised call in JIT variants, one call
  per distinct texel in scalar variants;
* anything else (a ``mesh_attribute``, a procedural texture): its values cannot be read at
  load.  :func:`readable` says so; the plugin then clamps them at evaluation and warns once.

The checks raise ``UsageError("hyde: ...")`` (a ``ValueError``) naming the parameter, the
texture key, the offending value and the accepted range.  :class:`Snapshot` keeps the last
accepted values so that a refused ``params.update()`` leaves the BSDF as it was.
"""
from __future__ import annotations

import warnings

import drjit as dr
import mitsuba as mi
import numpy as np

from hyde_bsdf.errors import UsageError
from hyde_bsdf.model.parameters import ALPHA, ETA, RMS_SLOPE

__all__ = ["probe", "texel_values", "readable",
           "values_of", "Reader", "check_roughness", "check_index", "check_reflectance", "Snapshot"]

#: relative slack on the printed bounds: a bound printed with 7 digits is itself accepted
_SLACK = 1e-6
#: wavelengths (nm) at which spectral textures are checked
_WAVELENGTHS = np.linspace(360.0, 830.0, 48)
#: lanes per vectorised evaluation of a bitmap's texels
_CHUNK = 1 << 22

#: traverse keys of a texture whose values are the texture's own values (not spectral coefficients)
_DATA_KEYS = ("value", "data", "values")


def _fmt(x):
    return f"{x:.7g}"


def texture_data(tex, params=None):
    """{key: float64 array} of a texture's traversable floating-point data (raw, as stored); ``params``: its
    ``mi.traverse`` if already made."""
    out = {}
    params = mi.traverse(tex) if params is None else params
    for key in params.keys():
        value = params[key]
        if isinstance(value, (str, bool)) or key.endswith("to_uv") or key.endswith("range"):
            continue
        try:
            arr = np.asarray(value, dtype=float).ravel()
        except (TypeError, ValueError):
            continue
        out[key] = arr
    return out


def _is_bitmap(tex):
    keys = mi.traverse(tex).keys()
    return "data" in keys and hasattr(tex, "resolution")


def _is_constant(tex):
    """Mitsuba's spatially uniform spectra: ``uniform``, ``srgb``, ``regular``, ``irregular``,
    ``d65``, ``blackbody`` (a ``mesh_attribute`` also says it is not spatially varying)."""
    return not tex.is_spatially_varying() and tex.class_name().endswith("Spectrum")


def _is_plain_checkerboard(tex):
    """A ``checkerboard`` of two constants (its two values are read at two points)."""
    return (tex.class_name() == "Checkerboard"
            and set(mi.traverse(tex).keys()) <= {"to_uv", "color0.value", "color1.value"})


def readable(tex):
    """True when every value the texture can return is read by :func:`values_of` at load."""
    return _is_constant(tex) or _is_bitmap(tex) or _is_plain_checkerboard(tex)


def _wavelength_sets():
    """Quadruples of wavelengths covering :data:`_WAVELENGTHS` (spectral variants), else [None]."""
    if not mi.is_spectral:
        return [None]
    return [_WAVELENGTHS[j::12] for j in range(12)]


def probe(tex, one=False):
    """Values of a spatially uniform texture (float64 array); None if it varies over the surface.

    Spectral variants: at 48 wavelengths 360-830 nm; RGB: the three channels; mono: one value.
    ``one``: read ``eval_1`` (how the plugin reads the roughness) instead of ``eval``.
    """
    if not _is_constant(tex):
        return None
    if tex.class_name() == "UniformSpectrum":
        # eval returns the stored value at every point and wavelength: read it, no kernel (a
        # scene of constants then loads without compiling one: its cold load, issue 31)
        value = float(np.asarray(mi.traverse(tex)["value"], dtype=float).ravel()[0])
        return _uniform_values(value, one)
    return _eval_at(tex, np.array([0.5]), np.array([0.5]), one)


def _uniform_values(value, one):
    """What :func:`probe` reads of a ``uniform`` texture of stored value ``value``."""
    return np.full(1 if one or mi.is_monochromatic else _WAVELENGTHS.size if mi.is_spectral else 3, value)


def _eval_at(tex, u, v, one):
    """tex.eval (or eval_1) at the points (u, v) over all wavelength sets: a flat float64 array.

    JIT variants: one kernel for all points and wavelengths (in chunks of 2^22 lanes), so a
    check inside an optimisation loop costs one launch per texture; ``eval_1`` does not depend
    on the wavelengths and is read once.
    """
    sets = [None] if one else _wavelength_sets()
    if dr.is_jit_v(mi.Float):
        n_sets = len(sets)
        uu, vv = np.tile(u, n_sets), np.tile(v, n_sets)
        wl = None if sets[0] is None else np.repeat(np.asarray(sets, float), u.size, axis=0)  # [lanes, 4]
        out = []
        for start in range(0, uu.size, _CHUNK):
            n = min(_CHUNK, uu.size - start)
            si = dr.zeros(mi.SurfaceInteraction3f, n)
            si.uv = mi.Point2f(mi.Float(uu[start:start + n]), mi.Float(vv[start:start + n]))
            if wl is not None:
                si.wavelengths = mi.UnpolarizedSpectrum(*(mi.Float(wl[start:start + n, j]) for j in range(4)))
            val = tex.eval_1(si) if one else tex.eval(si)
            # a constant texture returns one lane: broadcast it
            # lane-major (lane, channel): the order of the scalar path below
            out.append(np.asarray(val * dr.full(mi.Float, 1.0, n), dtype=float).T.ravel())
        return np.concatenate(out) if out else np.zeros(0)
    out = []
    for wl in sets:
        for uu, vv in zip(u, v):
            si = dr.zeros(mi.SurfaceInteraction3f)
            si.uv = mi.Point2f(float(uu), float(vv))
            if wl is not None:
                si.wavelengths = mi.UnpolarizedSpectrum(*map(float, wl))
            val = tex.eval_1(si) if one else tex.eval(si)
            out.append(np.asarray(val, dtype=float).ravel())
    return np.concatenate(out) if out else np.zeros(0)


def texel_values(tex, one=False):
    """A bitmap's values as ``eval`` (``eval_1`` with ``one``) returns them at every texel centre.

    Returns a flat float64 array, or None when ``tex`` is not a bitmap.  The texel centres
    ((x + 1/2) / W, (y + 1/2) / H) are mapped back through the inverse of ``to_uv``, so the
    bitmap is read at its texels whatever its transform and filter.  Scalar variants evaluate
    one point per distinct texel (8-bit maps have few).
    """
    if not _is_bitmap(tex):
        return None
    res = [int(x) for x in np.asarray(tex.resolution()).ravel()[:2]]
    w, h = res[0], res[1]
    xs, ys = np.meshgrid((np.arange(w) + 0.5) / w, (np.arange(h) + 0.5) / h)
    u, v = xs.ravel(), ys.ravel()
    if not dr.is_jit_v(mi.Float):
        data = np.asarray(mi.traverse(tex)["data"])
        rows = data.reshape(h * w, -1)
        _, first = np.unique(rows, axis=0, return_index=True)
        u, v = u[first], v[first]
    return _eval_in_texture_space(tex, u, v, one)


def _eval_in_texture_space(tex, u, v, one):
    """Evaluate at texture-space points (u, v): mapped back through the inverse of ``to_uv``."""
    params = mi.traverse(tex)
    if "to_uv" in params.keys():
        inv = params["to_uv"].inverse()
        m = np.asarray(inv.matrix, dtype=float).reshape(3, 3)
        pts = m @ np.stack([u, v, np.ones_like(u)])
        u, v = pts[0] / pts[2], pts[1] / pts[2]
    return _eval_at(tex, u, v, one)


def values_of(tex, one=False):
    """Every value the texture can return, read through its ``eval``; None when not readable."""
    if _is_constant(tex):
        return probe(tex, one)
    if _is_plain_checkerboard(tex):      # the centres of a color0 and a color1 square
        return _eval_in_texture_space(tex, np.array([0.25, 0.75]), np.array([0.25, 0.25]), one)
    return texel_values(tex, one)


def _where(name, tex, arr, bad):
    """'NAME.KEY = VALUE' (a constant) or 'NAME.KEY texel value VALUE (n of N values read)'."""
    keys = [k for k in mi.traverse(tex).keys() if k.split(".")[-1] in _DATA_KEYS]
    key = f"{name}.{keys[0]}" if len(keys) == 1 else name
    counts = "" if arr.size == 1 else f" ({int(bad.sum())} of {arr.size} values read)"
    if tex.is_spatially_varying():
        return f"{key} texel value {float(arr[bad][0])!r}{counts}"
    return f"{key} = {float(arr[bad][0])!r}{counts}"


class Reader:
    """Reads the textures' data and values for the checks, remembering what did not change.

    * Data and values are remembered until :meth:`forget` (the plugin forgets the textures an
      update changed): eta and k are checked together, and an update of one does not read the
      other again.
    * A bitmap whose ``eval`` (``eval_1``) returns its stored data unchanged (float data stored
      ``raw``, one value per texel; in spectral variants ``eval`` returns one value per texel and
      wavelength, so only ``eval_1``, the roughness, can qualify there) is read from its data once
      that is shown: its values
      read through ``eval`` equal its data, on data not all 0 or 1 (the only values the 8-bit /255
      and sRGB conversions leave unchanged).  From then on a check reads the data once (a read-back
      of an array :meth:`SceneParameters.update` has evaluated) and launches no kernel.
    """

    def __init__(self):
        self.data, self.values, self.plain, self.traversed = {}, {}, {}, {}

    def traverse(self, tex):
        """``mi.traverse(tex)``, made once per texture: its values are views of the texture's members (they
        follow every assignment), and each ``mi.traverse`` builds a class (host time at every update)."""
        made = self.traversed.get(id(tex))
        if made is None or made[0] is not tex:
            made = self.traversed[id(tex)] = (tex, mi.traverse(tex))
        return made[1]

    def forget(self, tex):
        """Read ``tex`` again at its next check (its values changed)."""
        self.data.pop(id(tex), None)
        for one in (False, True):
            self.values.pop((id(tex), one), None)

    def clear(self):
        self.data.clear()
        self.values.clear()
        self.traversed.clear()

    def raw(self, tex):
        """:func:`texture_data` of ``tex``, read once per change."""
        if id(tex) not in self.data:
            self.data[id(tex)] = texture_data(tex, self.traverse(tex))
        return self.data[id(tex)]

    def __call__(self, tex, one=False):
        """:func:`values_of` ``(tex, one)``, read once per change (None when not readable)."""
        key = (id(tex), one)
        if key not in self.values:
            self.values[key] = self._read(tex, one)
        return self.values[key]

    def _read(self, tex, one):
        key = (id(tex), one)
        raw = self.raw(tex)
        if tex.class_name() == "UniformSpectrum" and "value" in raw and raw["value"].size == 1:
            return _uniform_values(float(raw["value"][0]), one)     # its one number, already read back
        data = raw.get("data")
        # the texture itself is kept with the proof: its id cannot be reused by another texture
        proved, size, n_values = self.plain.get(key, (None, 0, 0))
        if data is not None and proved is tex and size == data.size:
            return _as_values(data, 1 if one else len(_wavelength_sets()), n_values)
        values = values_of(tex, one)
        if (values is not None and data is not None and np.isfinite(data).all()
                and not np.isin(data, (0.0, 1.0)).all()):
            expected = _as_values(data, 1 if one else len(_wavelength_sets()), values.size)
            if expected is not None and np.allclose(values, expected, rtol=1e-6, atol=0.0):
                self.plain[key] = (tex, data.size, values.size)
        return values


def _as_values(data, n_sets, size):
    """A one-value-per-texel bitmap's data in the order :func:`_eval_at` reads its ``size`` values
    ([wavelength set][texel][wavelength or channel]: the same value at every wavelength); None
    when ``size`` does not fit that layout."""
    per = size // (n_sets * data.size)
    if per < 1 or n_sets * data.size * per != size:
        return None
    return np.broadcast_to(data.reshape(1, -1, 1), (n_sets, data.size, per)).ravel()


def _raw_finite(name, tex, accepted="", reader=None):
    """Non-finite data anywhere (including leaves of textures that cannot be evaluated at load).
    ``reader``: a :class:`Reader` (reads each texture once per change)."""
    for key, arr in (reader.raw(tex) if reader is not None else texture_data(tex)).items():
        if not np.isfinite(arr).all():
            raise UsageError(f"hyde: parameter '{name}' ({name}.{key}) contains NaN or infinite values"
                             + (f"; accepted range {accepted}" if accepted else ""))


def check_roughness(name, tex, scale, reader=None):
    """Roughness values finite, >= 0 and <= the upper bound; values in [0, lower bound) are
    floored there at evaluation (as a mesh of roughconductor with alpha = 0 renders a mirror),
    with one warning.  ``scale``: 1 for rms_slope, 1/sqrt(2) for alpha.  ``reader``: a
    :class:`Reader`.  Returns the values read (None if not readable)."""
    lo, hi = (RMS_SLOPE if scale == 1.0 else ALPHA)
    rng = f"[{_fmt(lo)}, {_fmt(hi)}]" + ("" if scale == 1.0 else f" (rms_slope [{RMS_SLOPE.lo:g}, {RMS_SLOPE.hi:g}])")
    reader = reader or Reader()
    _raw_finite(name, tex, rng, reader)
    values = reader(tex, one=True)
    if values is None:
        return None
    bad = ~np.isfinite(values) | (values < 0) | (values > hi * (1 + _SLACK))
    if bad.any():
        raise UsageError(f"hyde: {name} must be a finite number in the accepted range {rng}, "
                         f"got {_where(name, tex, values, bad)}")
    low = values < lo * (1 - _SLACK)
    if low.any():
        warnings.warn(f"hyde: {name} below the lower bound {_fmt(lo)} ({_where(name, tex, values, low)}) "
                      f"is floored to {_fmt(lo)} (a near-mirror; 0 is roughconductor's mirror limit)",
                      RuntimeWarning, stacklevel=3)
    return values


def check_index(eta, k, reader=None):
    """eta, k finite, in [0, ETA.hi] wherever they can be read, and not both 0 everywhere.
    ``reader``: a :class:`Reader` (the plugin's, which does not read again a texture that did
    not change)."""
    reader = reader or Reader()
    _raw_finite("eta", eta, f"[0, {ETA.hi:g}]", reader)
    _raw_finite("k", k, f"[0, {ETA.hi:g}]", reader)
    read = {}
    for name, tex in (("eta", eta), ("k", k)):
        values = reader(tex)
        read[name] = values
        if values is None:
            continue
        bad = ~np.isfinite(values) | (values < 0) | (values > ETA.hi)
        if bad.any():
            raise UsageError(f"hyde: parameter '{name}' must be finite and in [0, {ETA.hi:g}] "
                             f"(index n + i k with k >= 0), got {_where(name, tex, values, bad)}")
    pe, pk = read["eta"], read["k"]
    if pe is not None and pk is not None and not eta.is_spatially_varying() and not k.is_spatially_varying():
        zero = (pe == 0) & (pk == 0)
        if zero.all():
            raise UsageError("hyde: eta and k cannot both be 0 (no material has index 0); "
                             "a dielectric has k = 0 and eta > 0")
        if zero.any() and mi.is_spectral and pe.size == pk.size == _WAVELENGTHS.size:
            order = np.concatenate(_wavelength_sets())
            zero_wl = np.sort(order[zero])
            warnings.warn(f"hyde: eta and k are both 0 at {_runs(zero_wl)} (a spectrum is 0 outside "
                          f"the wavelengths it is given at); the index is taken as 1 there (no "
                          f"reflection): give eta over 360-830 nm", RuntimeWarning, stacklevel=3)


def _runs(wl):
    step = _WAVELENGTHS[1] - _WAVELENGTHS[0]
    runs, start, prev = [], None, None
    for w in list(wl) + [None]:
        if w is not None and start is not None and w - prev <= step * 1.01:
            prev = w
            continue
        if start is not None:
            runs.append(f"{start:.0f}-{prev:.0f} nm")
        start = prev = w
    return ", ".join(runs)


def check_reflectance(tex, reader=None, name="specular_reflectance", hi=None):
    """specular_reflectance finite and >= 0 wherever it can be read (values > 1 are the user's
    choice, as in roughconductor: not physical); ``name``/``hi``: another reflectance with an upper
    bound (diffuse_reflectance, an albedo: <= 1).  ``reader``: a :class:`Reader`.  Returns the
    mean of the values read (None when not readable)."""
    reader = reader or Reader()
    _raw_finite(name, tex, reader=reader)
    values = reader(tex)
    if values is None:
        return None
    bad = ~np.isfinite(values) | (values < 0) | ((values > hi) if hi is not None else False)
    if bad.any():
        accepted = ">= 0" if hi is None else f"in [0, {hi:g}]"
        raise UsageError(f"hyde: parameter '{name}' must be finite and {accepted}, got "
                         + _where(name, tex, values, bad))
    return float(np.mean(values))


class Snapshot:
    """The last accepted traversable values of a set of textures, restorable after a refusal.

    Dr.Jit arrays are values: keeping a reference to the accepted array is a copy that a
    later ``params[key] = ...`` does not change.
    """

    def __init__(self, textures, reader=None):
        # traverse hands out the texture's own member: keep a copy (a new reference to the
        # accepted JIT variable; scalar arrays are copied).  ``reader``: a :class:`Reader` (its traversals)
        self.saved = [(tex, {key: _copy(value) for key, value in
                             _leaves(tex, reader.traverse(tex) if reader is not None else None)})
                      for tex in textures]

    def restore(self):
        for tex, values in self.saved:
            params = mi.traverse(tex)
            changed = False
            for key, value in values.items():
                if key in params.keys():
                    params[key] = _copy(value)
                    changed = True
            if changed:
                params.update()


def _copy(value):
    if isinstance(value, (int, float)):
        return value
    return dr.copy(value)


def _leaves(tex, params=None):
    params = mi.traverse(tex) if params is None else params
    for key in params.keys():
        value = params[key]
        if isinstance(value, (str, bool)) or key.endswith("to_uv"):
            continue
        yield key, value
