"""Mitsuba's tabulated complex indices (``data/ior``): the one place that turns a material name
into files.

A material name is accepted only if it is exactly one of the tables Mitsuba ships
(:func:`known_materials`: "Au", "Cu_palik", ...): no path, no ``../``, no file elsewhere on
Mitsuba's search path.  The plugin and ``export`` both go through :func:`material_files`; a
refusal names the (cut) name and the accepted ones.
"""
from __future__ import annotations

import importlib.util
from functools import lru_cache
from pathlib import Path

from hyde_bsdf.errors import UsageError, shorten

__all__ = ["ior_folder", "known_materials", "material_files"]


def ior_folder() -> Path | None:
    """Mitsuba's ``data/ior`` folder, located without importing Mitsuba (None if not installed;
    an editable/alias install has no package folder but an origin inside it)."""
    try:
        spec = importlib.util.find_spec("mitsuba")
    except (ImportError, ValueError):
        return None
    if spec is None:
        return None
    if spec.submodule_search_locations:
        folder = Path(list(spec.submodule_search_locations)[0])
    elif spec.origin:
        folder = Path(spec.origin).parent
    else:
        return None
    return folder / "data" / "ior"


@lru_cache(maxsize=1)
def known_materials() -> tuple:
    """The names of Mitsuba's ``data/ior`` tables that have both ``.eta.spd`` and ``.k.spd``."""
    folder = ior_folder()
    if folder is None or not folder.is_dir():
        return ()
    names = {p.name[:-len(".eta.spd")] for p in folder.glob("*.eta.spd")}
    return tuple(sorted(n for n in names if (folder / f"{n}.k.spd").is_file()))


def _examples(name, known) -> list:
    """A few names to suggest: the closest to ``name``, then the common metals."""
    import difflib

    close = difflib.get_close_matches(name, known, n=3) if isinstance(name, str) and len(name) < 100 else []
    return list(dict.fromkeys(close + [m for m in ("Au", "Ag", "Al", "Cu", "Cr") if m in known]))


def material_files(name) -> tuple:
    """(eta file, k file) of the ``data/ior`` material ``name``; UsageError unless ``name`` is
    exactly one of :func:`known_materials`."""
    known = known_materials()
    if not isinstance(name, str) or name not in known:
        listed = (f"one of the {len(known)} names in Mitsuba's data/ior folder, e.g. {', '.join(_examples(name, known))}"
                  if known else "none: Mitsuba is not installed")
        raise UsageError(f"material {shorten(name)} is not one of Mitsuba's data/ior tables ({listed})")
    folder = ior_folder()
    return folder / f"{name}.eta.spd", folder / f"{name}.k.spd"
