"""The process's run-time tuning for MoM workers: OpenBLAS threads and glibc's heap.

Not physics: the paper's equations live in :mod:`hyde_bsdf.mom.solver` and its solvers.  A pool worker runs
single-threaded BLAS (the partitions already keep every core busy; a 2-thread LU of a 500-unknown partition is
10x slower here) and keeps freed heap blocks (:func:`hyde_bsdf.resources.keep_freed_memory`).
"""
from __future__ import annotations

import ctypes

from hyde_bsdf.resources import keep_freed_memory

__all__ = ["openblas_libs", "limit_blas_threads", "restore_blas_threads", "keep_freed_memory", "worker_init"]


def openblas_libs():
    """(set_num_threads, get_num_threads) ctypes functions of every OpenBLAS loaded in this process.

    NumPy's and SciPy's wheels each bundle OpenBLAS; we reach their thread
    controls through ctypes (what threadpoolctl does) and skip any we cannot find.
    """
    try:
        with open("/proc/self/maps") as fh:  # closed at once (no ResourceWarning)
            maps = fh.read().split("\n")
    except OSError:  # not Linux: leave the BLAS alone
        return []
    paths = {line.split()[-1] for line in maps if "openblas" in line.lower() and line.split()[-1].startswith("/")}
    found = []
    for path in sorted(paths):
        try:
            lib = ctypes.CDLL(path)
        except OSError:
            continue
        for suffix in ("64_", "", "_64_"):
            set_fn = getattr(lib, "scipy_openblas_set_num_threads" + suffix, None)
            get_fn = getattr(lib, "scipy_openblas_get_num_threads" + suffix, None)
            if set_fn is not None and get_fn is not None:
                found.append((set_fn, get_fn))
                break
        else:
            set_fn = getattr(lib, "openblas_set_num_threads", None)
            get_fn = getattr(lib, "openblas_get_num_threads", None)
            if set_fn is not None and get_fn is not None:
                found.append((set_fn, get_fn))
    return found


def limit_blas_threads(n=1):
    """Limit OpenBLAS to n threads in this process; returns the previous counts (for restoring)."""
    previous = []
    for set_fn, get_fn in openblas_libs():
        previous.append((set_fn, int(get_fn())))
        set_fn(int(n))
    return previous


def restore_blas_threads(previous):
    for set_fn, count in previous:
        set_fn(count)


def worker_init():
    limit_blas_threads(1)
    keep_freed_memory()
