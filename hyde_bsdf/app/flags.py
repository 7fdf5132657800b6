"""The command line's names for the library's parameters: one table for every message it prints.

The library's messages name what sets a value -- a parameter, or a function -- in backquotes
(``lower `spp```, ``give `references```); the command line prints the flag that sets it instead
(``lower --spp``, ``give --reference``).  :func:`hyde_bsdf.app.cli.main` passes every error and
warning line through :func:`for_command_line`; a name without a flag keeps its backquotes.
"""
from __future__ import annotations

import re

__all__ = ["FLAGS", "for_command_line"]

#: library name -> the command line's flag
FLAGS = {
    "spp": "--spp", "seed": "--seed", "chunks": "--chunks", "params": "-D", "res": "--res",
    "iterations": "--iterations", "map_size": "--map-size", "prefix": "--target", "cameras": "--camera",
    "lights": "--light", "references": "--reference", "masks": "--mask", "tiles": "--tiles",
    "workers": "--workers", "n0": "--n0", "k0": "--k0", "select_model": "--model auto",
    "resolution": "--resolution", "fit": "--fit", "extrapolate": "--extrapolate",
}
_NAME = re.compile(r"`([A-Za-z_][A-Za-z0-9_]*)`")


def for_command_line(message: str) -> str:
    """``message`` with each backquoted library name that has a flag replaced by the flag."""
    return _NAME.sub(lambda m: FLAGS.get(m.group(1), m.group(0)), str(message))
