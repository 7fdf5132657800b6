"""Memory of a differentiable render: the estimate, and the check before an inversion starts.
"""
from __future__ import annotations

from hyde_bsdf.io.memory import available_bytes, check_memory as memory_check

__all__ = ["AD_BYTES_FIXED", "AD_BYTES_PER_SAMPLE", "AD_FORWARD_BYTES_PER_SAMPLE", "estimate_memory", "check_memory",
           "tiles_memory_check"]

#: peak memory of one differentiable render (reverse mode through ``path``): a fixed part plus
#: bytes per sample (measured: 1.4-1.5 kB/sample spectral polarized sphere at 64-128 px, 16 spp;
#: 0.8-1.2 kB mono polarized plane, 3 x 80-160 px, 4 spp; 2026-12-02, benchmarks/bench_capture_scale.py
#: --memory, the calibrated plane at 4 spp, 35 k / 142 k / 322 k px: peak RSS 0.39 / 1.07 / 1.87 GiB,
#: i.e. 1.2-1.4 kB/sample + ~0.2 GiB; the figures below have a margin of ~1.5)
AD_BYTES_FIXED = 400 * 2**20


AD_BYTES_PER_SAMPLE = 2048
#: the uncertainty step's forward-mode renders (one per fitted map, ``uncertainty_spp`` samples each, one
#: at a time): bytes per sample (measured 2026-12-02, bench_capture_scale.py --memory --uncertainty, 16 spp,
#: 35 k / 142 k px: peak RSS 0.69 / 1.97 GiB, ~0.8 kB/sample; with a margin).  At the default 16 spp
#: against the step's 4 it is the larger of the two: it sets the peak
AD_FORWARD_BYTES_PER_SAMPLE = 1024


def estimate_memory(width: int, height: int, spp: int, uncertainty_spp: int = 0) -> int:
    """Estimated peak memory (bytes) of an inversion on a ``width`` x ``height`` film: the larger of one
    optimisation step at ``spp`` and one forward-mode pass of the uncertainty step at ``uncertainty_spp``
    (0: no uncertainty step)."""
    pixels = int(width) * int(height)
    return AD_BYTES_FIXED + max(AD_BYTES_PER_SAMPLE * pixels * int(spp),
                                AD_FORWARD_BYTES_PER_SAMPLE * pixels * int(uncertainty_spp))


def _mem_available():
    return available_bytes()


def _what(spp, uncertainty_spp) -> str:
    return (f"{spp} spp" + (f" (and the uncertainty step at {uncertainty_spp} spp)" if uncertainty_spp else "")
            + f" ({AD_BYTES_PER_SAMPLE} B per sample" + (f", forward mode {AD_FORWARD_BYTES_PER_SAMPLE} B"
                                                          if uncertainty_spp else "")
            + f" + {AD_BYTES_FIXED // 2**20} MiB)")


def check_memory(width: int, height: int, spp: int, hint: str, uncertainty_spp: int = 0) -> int:
    """UsageError when :func:`estimate_memory` exceeds the available memory; returns the estimate."""
    need, avail = estimate_memory(width, height, spp, uncertainty_spp), _mem_available()
    if avail is not None:
        memory_check(need, f"one optimisation step on the {width}x{height} film at {_what(spp, uncertainty_spp)}",
                     f"lower {hint}", available=avail)
    return need


def tiles_memory_check(pixels: int, spp: int, concurrent: int = 1, available: int | None = None,
                       uncertainty_spp: int = 0) -> int:
    """UsageError when ``concurrent`` tiles at once, each :func:`estimate_memory` of ``pixels`` (the largest
    tile's film crops, all pictures together: one step renders them all) exceed the available memory;
    names the options that lower it.  Returns the estimate."""
    need = estimate_memory(int(pixels), 1, spp, uncertainty_spp) * int(concurrent)
    memory_check(need, f"{concurrent} tile(s) at once, the largest with {int(pixels)} px of film crops at "
                 f"{_what(spp, uncertainty_spp)} each", "use more --tiles (smaller crops), a lower --spp or fewer "
                 "--workers", available=_mem_available() if available is None else available)
    return need
