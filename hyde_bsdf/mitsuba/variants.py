"""Choosing a Mitsuba variant safely.

Dr.Jit 1.5's LLVM back end aborts the whole process ("LLVM ERROR: Cannot select
... fminimum") when it finds Debian 12's libLLVM-15.  Before any ``llvm_*``
variant is selected we ask ``drjit.detail.llvm_version()`` which libLLVM was
found; on a missing or too old one we fall back to the matching ``scalar_*``
variant with a clear message (or raise, if the caller forbids the fallback).

``cuda_*`` variants need an NVIDIA GPU and its driver; without one, Mitsuba's
``set_variant`` raises an ``ImportError`` ("the CUDA backend hasn't been
initialized").  :func:`usable_variant` turns that into a :class:`VariantUnavailable`
that names the ``llvm_*`` twin to use instead (or falls back to it, with a warning).
:func:`usable_variants` lists every variant that can be selected here (the ``hyde``
plugin is registered in all of them by ``hyde_bsdf.register()``).
"""
from __future__ import annotations

import warnings

__all__ = ["MIN_LLVM", "VariantUnavailable", "llvm_usable", "cuda_usable", "usable_variant",
           "usable_variants", "set_variant"]

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


def cuda_usable() -> tuple[bool, str]:
    """Whether Dr.Jit's CUDA back end can run here (a GPU and driver), and why not if it cannot."""
    import drjit as dr

    try:
        ok = bool(dr.has_backend(dr.JitBackend.CUDA))
    except Exception as exc:  # pragma: no cover - Dr.Jit without the query
        return False, f"Dr.Jit cannot query its CUDA back end ({exc})"
    if not ok:
        return False, "Dr.Jit found no CUDA device (an NVIDIA GPU with its driver is needed)"
    return True, "CUDA device found"


def _cpu_twin(variant: str) -> str:
    return "llvm_" + variant.split("_", 1)[1]


def usable_variants() -> list[str]:
    """The compiled variants that can be selected on this machine (LLVM and CUDA checked)."""
    import mitsuba as mi

    llvm_ok, cuda_ok = llvm_usable()[0], cuda_usable()[0]
    return [v for v in mi.variants()
            if (not v.startswith("llvm_") or llvm_ok) and (not v.startswith("cuda_") or cuda_ok)]


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
    if variant.startswith("cuda_"):
        ok, why = cuda_usable()
        if ok:
            return variant
        twin = _cpu_twin(variant)
        if not fallback:
            raise VariantUnavailable(f"variant={variant!r} needs a CUDA GPU: {why}; use {twin!r} "
                                     f"(the same variant on the CPU) instead")
        warnings.warn(f"{why}; using {twin!r} instead of {variant!r}", RuntimeWarning, stacklevel=2)
        return usable_variant(twin, fallback=True)
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
    try:
        mi.set_variant(chosen)
    except ImportError as exc:   # a CUDA device that is present but cannot be initialised
        raise VariantUnavailable(f"variant={chosen!r} cannot be initialised here ({exc}); "
                                 f"use {_cpu_twin(chosen)!r} instead") from exc
    return chosen
