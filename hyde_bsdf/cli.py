"""``hyde-bsdf`` command line: one sub-command per module.

Each sub-command lives in the module that does the work, as a function
``cli_main(argv) -> int``; this file only dispatches, so that importing the
package stays cheap and no sub-command drags in Mitsuba unless it needs it.
"""
from __future__ import annotations

import importlib
import sys

#: sub-command -> (module, one-line help)
COMMANDS = {
    "demo": ("hyde_bsdf.render.demo", "the main job: demo pictures into a folder"),
    "render": ("hyde_bsdf.render.renderer", "render a scene to a Stokes EXR and polarization PNGs"),
    "fit": ("hyde_bsdf.fit.mueller_fit", "fit n, k, rms_slope to a Mueller-matrix CSV"),
    "invert": ("hyde_bsdf.render.inverse", "recover roughness and index from a Stokes image"),
    "validate": ("hyde_bsdf.report.build", "run the validation report"),
}


def main(argv: list[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    if not argv or argv[0] in ("-h", "--help") or argv[0] not in COMMANDS:
        print("usage: hyde-bsdf COMMAND [options]\n\ncommands:")
        for name, (_, text) in COMMANDS.items():
            print(f"  {name:10s} {text}")
        return 0 if argv and argv[0] in ("-h", "--help") else 2
    module = importlib.import_module(COMMANDS[argv[0]][0])
    return int(module.cli_main(argv[1:]) or 0)


if __name__ == "__main__":
    sys.exit(main())
