"""Choosing a Mitsuba variant safely.

Dr.Jit 1.5's LLVM back end aborts the whole process ("LLVM ERROR: Cannot select
... fminimum") when it finds Debian 12's libLLVM-15.  Before any ``llvm_*``
variant is selected we ask ``drjit.detail.llvm_version()`` which libLLVM was
found; on a missing or too old one we fall back to the matching ``scalar_*``
variant with a clear message (or raise, if the caller forbids the fallback).
"""
from __future__ import annotations

import warnings

__all__ = ["MIN_LLVM", "llvm_usable", "usable_variant", "set_variant"]

#: Oldest libLLVM major version with which Dr.Jit 1.5 does not abort.
MIN_LLVM = 16


class VariantUnavailable(RuntimeError):
    """The requested Mitsuba variant cannot be used on this machine."""


def llvm_usable() -> tuple[bool, str]:
    """Whether Dr.Jit's LLVM back end can run here, and why not if it cannot."""
    import drjit as dr

    try:
        version = dr.detail.llvm_version()
    except Exception as exc:  # no libLLVM found at all
        return False, f"Dr.Jit found no libLLVM ({exc})"
    if version is None or tuple(version)[:1] < (MIN_LLVM,):
        return False, (f"Dr.Jit found libLLVM {'.'.join(map(str, version or ()))}; "
                       f"version >= {MIN_LLVM} is needed (apt-get install libllvm19)")
    return True, f"libLLVM {'.'.join(map(str, version))}"


def usable_variant(variant: str, fallback: bool = True) -> str:
    """The variant to use for ``variant``: itself, or its ``scalar_*`` twin.

    ``llvm_ad_spectral_polarized`` becomes ``scalar_spectral_polarized`` when the
    LLVM back end is unusable (``llvm_ad_rgb`` -> ``scalar_rgb`` and so on).
    With ``fallback=False`` a :class:`VariantUnavailable` is raised instead.
    """
    import mitsuba as mi

    if variant not in mi.variants():
        raise VariantUnavailable(
            f"variant={variant!r} is not built into this Mitsuba; available: {', '.join(mi.variants())}")
    if not variant.startswith("llvm_"):
        return variant
    ok, why = llvm_usable()
    if ok:
        return variant
    scalar = "scalar_" + variant.split("_", 2)[2]
    if not fallback or scalar not in mi.variants():
        raise VariantUnavailable(f"variant={variant!r} needs Dr.Jit's LLVM back end: {why}")
    warnings.warn(f"{why}; using {scalar!r} instead of {variant!r}", RuntimeWarning, stacklevel=2)
    return scalar


def set_variant(variant: str, fallback: bool = True) -> str:
    """``mi.set_variant`` after the LLVM check; returns the variant actually set."""
    import mitsuba as mi

    chosen = usable_variant(variant, fallback=fallback)
    mi.set_variant(chosen)
    return chosen
