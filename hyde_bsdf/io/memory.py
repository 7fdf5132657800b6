"""The one memory check: what is available, in readable units, before every large allocation.

:func:`available_bytes` reads ``/proc/meminfo`` (``MemAvailable``; the only place in the package
that does), falling back to ``sysconf`` free pages, or None where neither exists.
:func:`check_memory` refuses, before the allocation, a need larger than what is available, with
a :class:`~hyde_bsdf.errors.UsageError` naming what needs it, both sizes in units that show them
(never "0.00 GiB") and the option that makes it smaller.
"""
from __future__ import annotations

import os

from hyde_bsdf.errors import UsageError

__all__ = ["available_bytes", "total_bytes", "format_bytes", "check_memory", "MEMINFO"]

#: the file the kernel reports memory in (tests point it elsewhere)
MEMINFO = "/proc/meminfo"
_UNITS = ("B", "KiB", "MiB", "GiB", "TiB", "PiB", "EiB")


def _meminfo(field: str) -> int | None:
    try:
        with open(MEMINFO, "rb") as fh:
            for line in fh.read(1 << 16).decode("ascii", "replace").splitlines():
                if line.startswith(field + ":"):
                    return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        pass
    return None


def _sysconf_pages(name: str) -> int | None:
    try:
        pages, size = os.sysconf(name), os.sysconf("SC_PAGE_SIZE")
    except (ValueError, OSError, AttributeError):
        return None
    return pages * size if pages > 0 and size > 0 else None


def available_bytes() -> int | None:
    """Memory available to new allocations (bytes): ``MemAvailable``, else the free pages, else None."""
    value = _meminfo("MemAvailable")
    return value if value is not None else _sysconf_pages("SC_AVPHYS_PAGES")


def total_bytes() -> int | None:
    """Installed memory (bytes): ``MemTotal``, else the physical pages, else None."""
    value = _meminfo("MemTotal")
    return value if value is not None else _sysconf_pages("SC_PHYS_PAGES")


def format_bytes(n) -> str:
    """``n`` bytes with a binary unit chosen so that the number is >= 1: '512 B', '3.5 MiB', '74.5 GiB'."""
    n = float(n)
    unit = 0
    while abs(n) >= 1024 and unit < len(_UNITS) - 1:
        n /= 1024
        unit += 1
    return f"{n:.0f} B" if unit == 0 else f"{n:.3g} {_UNITS[unit]}" if n < 100 else f"{n:.0f} {_UNITS[unit]}"


def check_memory(need, what: str, option: str, available: int | None = None, fraction: float = 1.0) -> int:
    """UsageError (before the allocation) when ``need`` bytes exceed ``fraction`` of the available
    memory (``available``, default :func:`available_bytes`; unknown: no refusal).  ``what`` names
    what needs it ("the 100000x100000 maps"), ``option`` what makes it smaller ("lower --map-size").
    Returns ``need``."""
    need = int(need)
    avail = available_bytes() if available is None else int(available)
    if avail is not None and need > fraction * avail:
        share = "" if fraction == 1.0 else f" ({fraction:.0%} of the {format_bytes(avail)} available)"
        room = format_bytes(fraction * avail) if fraction != 1.0 else format_bytes(avail)
        raise UsageError(f"{what}: about {format_bytes(need)} of memory needed, but only {room} is available"
                         f"{share}; {option}")
    return need
