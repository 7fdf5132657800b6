"""Memory of a differentiable render: the estimate, and the check before an inversion starts.

May import: the standard library, :mod:`hyde_bsdf.errors`.
"""
from __future__ import annotations

from hyde_bsdf.errors import UsageError

__all__ = ["AD_BYTES_FIXED", "AD_BYTES_PER_SAMPLE", "estimate_memory", "check_memory"]

#: peak memory of one differentiable render (reverse mode through ``path``): a fixed part plus
#: bytes per sample (measured: 1.4-1.5 kB/sample spectral polarized sphere at 64-128 px, 16 spp;
#: 0.8-1.2 kB mono polarized plane, 3 x 80-160 px, 4 spp; the figure below has a margin)
AD_BYTES_FIXED = 400 * 2**20


AD_BYTES_PER_SAMPLE = 2048


def estimate_memory(width: int, height: int, spp: int) -> int:
    """Estimated peak memory (bytes) of one optimisation step on a ``width`` x ``height`` film."""
    return AD_BYTES_FIXED + AD_BYTES_PER_SAMPLE * int(width) * int(height) * int(spp)


def _mem_available():
    try:
        with open("/proc/meminfo") as fh:
            for line in fh:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        pass
    return None


def check_memory(width: int, height: int, spp: int, hint: str) -> int:
    """UsageError when :func:`estimate_memory` exceeds the available memory; returns the estimate."""
    need, avail = estimate_memory(width, height, spp), _mem_available()
    if avail is not None and need > avail:
        raise UsageError(f"one optimisation step on the {width}x{height} film at {spp} spp needs about "
                         f"{need / 2**30:.1f} GiB ({AD_BYTES_PER_SAMPLE} B per sample + "
                         f"{AD_BYTES_FIXED // 2**20} MiB), but only {avail / 2**30:.1f} GiB is available; "
                         f"lower {hint}")
    return need
