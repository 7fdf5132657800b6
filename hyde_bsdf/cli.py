"""Compatibility: ``hyde_bsdf.cli.main`` for console scripts installed before the command line
moved to :mod:`hyde_bsdf.app.cli` (an editable install keeps its old entry script until it is
reinstalled).  New code imports :mod:`hyde_bsdf.app.cli`."""
from hyde_bsdf.app.cli import main

__all__ = ["main"]

if __name__ == "__main__":
    import sys

    sys.exit(main())
