"""What work costs and what the machine has: memory, and exclusive use of an output.

* :data:`COSTS`, the one table of what work costs: every byte and time model the package checks
  work against.  ``benchmarks/bench_resources.py`` measures each entry and prints the measured
  value beside the table's (the table keeps a margin above the measurement: ratio >= 1);
  rerun it after a change that moves a cost, and copy what it prints here.
* :func:`available_memory` (the only reader of ``/proc/meminfo``) and :func:`check_memory`, which
  refuses work before its allocation with one line naming what needs the memory, both sizes in
  units that show them (never "0.00 GiB") and the parameter that makes it smaller.
* :class:`OutputLock`: one writer per output at a time (a second run fails at once, one line).
* :func:`wait_limit`: how long each kind of wait may last (:data:`TIMEOUTS`, changed by environment
  variables); every wait on a network peer, a task or a child process is bounded by one.
"""
from __future__ import annotations

import contextlib
import dataclasses
import errno
import fcntl
import hashlib
import os
import tempfile
from pathlib import Path

from hyde_bsdf.errors import UsageError, shorten

__all__ = ["Costs", "COSTS", "available_memory", "total_memory", "format_bytes", "check_memory", "render_bytes",
           "inversion_bytes", "dense_solve_cost", "OutputLock", "MEMINFO", "TIMEOUTS", "wait_limit",
           "keep_freed_memory"]

MiB = 2**20


@dataclasses.dataclass(frozen=True)
class Costs:
    """The byte (B) and time (s) models; peak memory is the process's peak resident size."""

    #: ``render``: peak RSS of a whole render and its EXR/PNG writes, fixed + per film pixel (a Stokes
    #: render in llvm_ad_spectral_polarized; a colour one in llvm_ad_rgb); samples per pixel barely count
    render_fixed_bytes: int = 400 * MiB
    render_stokes_bytes_per_pixel: int = 800
    render_colour_bytes_per_pixel: int = 250
    #: ``invert``: one differentiable render (reverse mode through ``path``; all pictures of a step
    #: together), fixed + per sample (pixels x spp); the uncertainty step's forward-mode renders, per sample
    ad_fixed_bytes: int = 400 * MiB
    ad_bytes_per_sample: int = 3072
    ad_forward_bytes_per_sample: int = 1024
    #: ``invert --maps``: float64 maps per texel: the truth, and per fitted parameter its value, gradient,
    #: Adam's two moments and the running average (counted, not measured)
    map_bytes_per_texel_fixed: int = 8
    map_bytes_per_texel_fitted: int = 5 * 8
    #: ``mom.scatter``: peak bytes per surface point while the surface is drawn (derivatives included)
    surface_bytes_per_point: int = 64
    #: ``mom.scatter``'s dense solve, one core: matrix fill per entry and region, LU per n^3 and
    #: polarisation, a lossless interior's (1/2 + D1)^-1 S1 per n^3
    dense_fill_seconds_per_entry: float = 2.2e-7
    dense_lu_seconds_per_n3: float = 6.5e-11
    dense_interior_seconds_per_n3: float = 5.5e-10
    #: ``mom.scatter``'s fast solver, CPU seconds per unknown (where it has not run yet)
    fast_seconds_per_unknown: float = 2e-3
    #: ``mom.estimate``'s model of the fast solver's time per partition (hyde_bsdf/mom/cost.py; fitted and checked
    #: by benchmarks/bench_mom_estimate.py): set-up per strong-part entry and region, per entry and skin-depth panel,
    #: per plane wave; solve per strong entry and per plane wave, each per right-hand side and region; far field per
    #: unknown, angle and right-hand side
    fast_fill_seconds_per_entry: float = 6.76e-7
    fast_panel_seconds_per_entry: float = 7.72e-7
    fast_wave_seconds: float = 0.0
    fast_band_seconds: float = 1.37e-9
    fast_sweep_seconds: float = 2.9e-8
    far_field_seconds: float = 5.65e-10
    #: ``export``: Mitsuba's loader holds this many copies of a ``.pbsdf`` table
    pbsdf_loader_copies: int = 2
    #: ``pbrdf``: peak bytes per direction beyond the caller's angle arrays: the (4, 4) float64 result (128 B)
    #: and the argument checks' temporaries; the model runs in blocks of 8192 directions (measured 154 B at 10^6
    #: directions, 135 B (resident) at 9x10^6 broadcast ones)
    pbrdf_bytes_per_direction: int = 160
    #: ``stokes``: peak bytes per raw value (pixel x frame) of frames or a superpixel mosaic, and of a
    #: bilinear (full-resolution) mosaic (measured 72-94 B and 270 B at 1-12 million values)
    stokes_bytes_per_value: int = 128
    stokes_bilinear_bytes_per_value: int = 384
    #: a CSV (``fit``'s measurements): peak bytes per value it can hold (one per comma or line end) while
    #: it is read and parsed (measured 18 B on NumPy's path, 48 B on the cell-by-cell one, at 1.6 million
    #: one-digit values, the densest a file can be)
    csv_bytes_per_value: int = 64
    #: disk, upper bounds: one plot file (the largest raster figure, a 16-element fit at 120 dpi, is
    #: 10.6 MB of RGBA; the largest vector one, the .pbsdf fit, ~30 MB), one history-CSV row
    plot_file_bytes: int = 64 * MiB
    history_row_bytes: int = 256


#: the table every estimate reads
COSTS = Costs()


def render_bytes(width: int, height: int, polarized: bool = True) -> int:
    """Peak memory (bytes) of rendering and writing a ``width`` x ``height`` film."""
    per_px = COSTS.render_stokes_bytes_per_pixel if polarized else COSTS.render_colour_bytes_per_pixel
    return COSTS.render_fixed_bytes + int(width) * int(height) * per_px


def inversion_bytes(pixels: int, spp: int, uncertainty_spp: int = 0) -> int:
    """Peak memory (bytes) of an inversion on ``pixels`` of film: the larger of one optimisation step at
    ``spp`` and one forward-mode pass of the uncertainty step at ``uncertainty_spp`` (0: none)."""
    return COSTS.ad_fixed_bytes + max(COSTS.ad_bytes_per_sample * int(pixels) * int(spp),
                                      COSTS.ad_forward_bytes_per_sample * int(pixels) * int(uncertainty_spp))


def dense_solve_cost(n: int, polarizations: int, regions: int, lossless_interior: bool) -> float:
    """CPU seconds of a dense MoM solve of ``n`` unknowns (``regions``: 1 for a PEC, 2 with an interior)."""
    seconds = COSTS.dense_fill_seconds_per_entry * regions * n * n + COSTS.dense_lu_seconds_per_n3 * polarizations * n**3
    return seconds + (COSTS.dense_interior_seconds_per_n3 * n**3 if lossless_interior else 0.0)


# ---------------------------------------------------------------------------
# memory

#: the file the kernel reports memory in (tests point it elsewhere)
MEMINFO = "/proc/meminfo"
_UNITS = ("B", "KiB", "MiB", "GiB", "TiB", "PiB", "EiB")


def _meminfo(field: str, pages: str) -> int | None:
    """``field`` of /proc/meminfo in bytes, else ``sysconf(pages)`` x the page size, else None."""
    try:
        with open(MEMINFO, "rb") as fh:
            for line in fh.read(1 << 16).decode("ascii", "replace").splitlines():
                if line.startswith(field + ":"):
                    return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        pass
    try:
        count, size = os.sysconf(pages), os.sysconf("SC_PAGE_SIZE")
    except (ValueError, OSError, AttributeError):
        return None
    return count * size if count > 0 and size > 0 else None


def available_memory() -> int | None:
    """Memory available to new allocations (bytes): ``MemAvailable``, else the free pages, else None."""
    return _meminfo("MemAvailable", "SC_AVPHYS_PAGES")


def total_memory() -> int | None:
    """Installed memory (bytes): ``MemTotal``, else the physical pages, else None."""
    return _meminfo("MemTotal", "SC_PHYS_PAGES")


def format_bytes(n) -> str:
    """``n`` bytes with a binary unit chosen so that the number is >= 1: '512 B', '3.5 MiB', '74.5 GiB'."""
    n, unit = float(n), 0
    while abs(n) >= 1024 and unit < len(_UNITS) - 1:
        n, unit = n / 1024, unit + 1
    return f"{n:.0f} B" if unit == 0 else f"{n:.3g} {_UNITS[unit]}" if n < 100 else f"{n:.0f} {_UNITS[unit]}"


def keep_freed_memory():
    """glibc only: keep freed blocks up to 256 MiB in the heap instead of returning them to the system (each MoM
    partition allocates and frees the same temporaries; handing them back costs a page fault per 4 KiB on the
    next use: a tenth of a Fig. 6 partition's CPU time was system time).  Process-wide: for processes of their
    own only, the MoM's pool workers and the validation scripts."""
    import ctypes

    try:
        libc = ctypes.CDLL("libc.so.6")
        libc.mallopt(-3, 256 * 2**20)      # M_MMAP_THRESHOLD
        libc.mallopt(-1, 512 * 2**20)      # M_TRIM_THRESHOLD
    except (OSError, AttributeError):      # not glibc
        pass


def check_memory(need, what: str, remedy: str, fraction: float = 1.0) -> int:
    """UsageError (before the allocation) when ``need`` bytes exceed ``fraction`` of
    :func:`available_memory` (unknown: no refusal); returns ``need``.  ``what`` names what needs it
    ("the 100000x100000 maps"), ``remedy`` what makes it smaller ("lower map_size")."""
    need, avail = int(need), available_memory()
    if avail is not None and need > fraction * avail:
        share = "" if fraction == 1.0 else f" ({fraction:.0%} of the {format_bytes(avail)} available)"
        raise UsageError(f"{what}: about {format_bytes(need)} of memory needed, but only "
                         f"{format_bytes(fraction * avail)} is available{share}; {remedy}")
    return need


# ---------------------------------------------------------------------------
# waits

#: the longest wait of each kind (seconds); HYDE_BSDF_<KIND>_TIMEOUT overrides: "connect" a dask
#: scheduler's connection and each question to it, "task" a pool or cluster without any task
#: finishing, "script" one validation script
TIMEOUTS = {"connect": 10.0, "task": 3600.0, "script": 3600.0}


def wait_limit(kind: str) -> tuple[float, str]:
    """(seconds, the environment variable that sets them) of a wait of ``kind`` (:data:`TIMEOUTS`);
    a value that is not a number > 0 is a UsageError naming the variable."""
    name = f"HYDE_BSDF_{kind.upper()}_TIMEOUT"
    text = os.environ.get(name, "").strip()
    try:
        seconds = float(text) if text else TIMEOUTS[kind]
    except ValueError:
        seconds = -1.0
    if not 0 < seconds < float("inf"):
        raise UsageError(f"{name} must be a number of seconds > 0, got {shorten(text)}")
    return seconds, name


# ---------------------------------------------------------------------------
# exclusive use of an output

class OutputLock:
    """Exclusive, non-blocking ``flock`` locks on output paths, one lock file per path in a per-user
    folder (``$XDG_RUNTIME_DIR`` or the temporary folder); released when the block ends or the
    process dies.  A path another run holds: UsageError naming it and that run's pid."""

    def __init__(self, paths, what: str = "output"):
        self.paths, self.what, self.fds = sorted({os.path.realpath(p) for p in paths}), what, []

    def __enter__(self):
        folder = Path(os.environ.get("XDG_RUNTIME_DIR") or tempfile.gettempdir()) / f"hyde-bsdf-locks-{os.geteuid()}"
        try:
            folder.mkdir(mode=0o700, exist_ok=True)
            for p in self.paths:
                self._lock(folder / (hashlib.sha256(os.fsencode(p)).hexdigest()[:32] + ".lock"), p)
        except BaseException:
            self.__exit__()
            raise
        return self

    def _lock(self, lock_path: Path, target: str) -> None:
        try:
            fd = os.open(lock_path, os.O_RDWR | os.O_CREAT | os.O_CLOEXEC, 0o600)
        except OSError as exc:
            raise UsageError(f"the lock file {shorten(lock_path)} cannot be used ({exc.strerror})") from None
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError as exc:
            holder = os.pread(fd, 32, 0).decode("ascii", "replace").strip() or "?"
            os.close(fd)
            if exc.errno in (errno.EWOULDBLOCK, errno.EACCES):
                raise UsageError(f"{self.what} {shorten(target)} is being written by another run (pid {holder}); "
                                 "wait for it to finish or write elsewhere") from None
            raise
        os.ftruncate(fd, 0)
        os.pwrite(fd, str(os.getpid()).encode(), 0)
        self.fds.append(fd)

    def __exit__(self, *exc):
        for fd in self.fds:
            with contextlib.suppress(OSError):
                os.close(fd)               # closing releases the flock
        self.fds = []
        return False
