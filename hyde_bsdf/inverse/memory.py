"""Memory of a differentiable render: the estimate, and the check before an inversion starts.

May import: the standard library, :mod:`hyde_bsdf.io.memory`.
"""
from __future__ import annotations

from hyde_bsdf.io.memory import available_bytes, check_memory as memory_check

__all__ = ["AD_BYTES_FIXED", "AD_BYTES_PER_SAMPLE", "estimate_memory", "check_memory", "tiles_memory_check"]

#: peak memory of one differentiable render (reverse mode through ``path``): a fixed part plus
#: bytes per sample (measured: 1.4-1.5 kB/sample spectral polarized sphere at 64-128 px, 16 spp;
#: 0.8-1.2 kB mono polarized plane, 3 x 80-160 px, 4 spp; the figure below has a margin)
AD_BYTES_FIXED = 400 * 2**20


AD_BYTES_PER_SAMPLE = 2048


def estimate_memory(width: int, height: int, spp: int) -> int:
    """Estimated peak memory (bytes) of one optimisation step on a ``width`` x ``height`` film."""
    return AD_BYTES_FIXED + AD_BYTES_PER_SAMPLE * int(width) * int(height) * int(spp)


def _mem_available():
    return available_bytes()


def check_memory(width: int, height: int, spp: int, hint: str) -> int:
    """UsageError when :func:`estimate_memory` exceeds the available memory; returns the estimate."""
    need, avail = estimate_memory(width, height, spp), _mem_available()
    if avail is not None:
        memory_check(need, f"one optimisation step on the {width}x{height} film at {spp} spp "
                     f"({AD_BYTES_PER_SAMPLE} B per sample + {AD_BYTES_FIXED // 2**20} MiB)", f"lower {hint}",
                     available=avail)
    return need


def tiles_memory_check(pixels: int, spp: int, concurrent: int = 1, available: int | None = None) -> int:
    """UsageError when ``concurrent`` tiles at once, each :func:`estimate_memory` of ``pixels`` (the largest
    tile's film crops, all pictures together: one step renders them all) at ``spp``, exceed the available
    memory; names the options that lower it.  Returns the estimate."""
    need = estimate_memory(int(pixels), 1, spp) * int(concurrent)
    memory_check(need, f"{concurrent} tile(s) at once, the largest with {int(pixels)} px of film crops at {spp} spp "
                 f"({AD_BYTES_PER_SAMPLE} B per sample + {AD_BYTES_FIXED // 2**20} MiB each)",
                 "use more --tiles (smaller crops), a lower --spp or fewer --workers",
                 available=_mem_available() if available is None else available)
    return need
