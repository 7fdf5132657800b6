"""``hyde-bsdf fit``: dispatch on the data file's kind.

A Mitsuba ``measured_polarized`` table (``.pbsdf`` or any file starting with the tensor-file
header) goes to :func:`hyde_bsdf.fit.pbsdf_fit.cli_main`; anything else is a Mueller-matrix CSV
for :func:`hyde_bsdf.fit.mueller_fit.cli_main`.  ``--help`` without a file shows both.
"""
from __future__ import annotations

from pathlib import Path

from hyde_bsdf.errors import UsageError
from hyde_bsdf.io.input_gate import STDIN, check_input

__all__ = ["is_pbsdf", "cli_main"]


def is_pbsdf(path) -> bool:
    """Whether ``path`` names a measured_polarized table (by its suffix or its header)."""
    p = Path(path)
    if p.suffix.lower() == ".pbsdf":
        return True
    try:       # sniff regular files only: a FIFO would block, stdin would lose its first bytes
        if check_input(p, "data file") == STDIN:
            return False
    except UsageError:
        return False        # the CSV reader's input gate refuses it with one line
    try:
        with open(p, "rb") as f:
            return f.read(12) == b"tensor_file\0"
    except OSError:
        return False


def cli_main(argv=None) -> int:
    argv = list(argv or [])
    positional = [a for a in argv if not a.startswith("-")]
    if positional and is_pbsdf(positional[0]):
        from hyde_bsdf.fit.pbsdf_fit import cli_main as pbsdf_main
        return pbsdf_main(argv)
    if not positional and any(a in ("-h", "--help") for a in argv):
        from hyde_bsdf.fit.pbsdf_fit import build_parser
        print(build_parser().format_help().replace("usage: hyde-bsdf fit", "usage: hyde-bsdf fit FILE.pbsdf", 1))
        print("----- Mueller-matrix CSV files -----")
    from hyde_bsdf.fit.mueller_fit import cli_main as csv_main
    return csv_main(argv)
