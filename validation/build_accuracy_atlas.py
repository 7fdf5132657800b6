"""Build the accuracy atlas (issue 32): the MoM runs, then the table shipped in hyde_bsdf/data/.

    python validation/build_accuracy_atlas.py run   [--checkpoints DIR] [--workers N | --dask ADDRESS]
    python validation/build_accuracy_atlas.py table [--checkpoints DIR] [-o hyde_bsdf/data/accuracy_atlas.npz]
    python validation/build_accuracy_atlas.py heldout [--checkpoints DIR]

``run`` solves the MoM for every surface and material of the grid (hyde_bsdf/mom/atlas.py: 36 surfaces x
5 materials, both polarisations, 10 incidence angles each) on a process pool of ``--workers`` (default 2)
or on a dask cluster (``--dask tcp://host:8786``; ``pip install hyde-bsdf[distributed]``), writing one
checkpoint per surface and material into ``--checkpoints`` (default out/atlas_runs) as each finishes.  Run
it again after a kill: it resumes with the tasks not yet done.  About 2-3 CPU hours on this machine's
cores (docs/validation.md has the measured time and the speed-up over dask workers); run it niced
(``nice -n 19``).

``table`` compares every model variant of the registry (shadowing x diffuse of hyde_bsdf.model, through
the 1-D reduction hyde_bsdf.mom.model1d) with the checkpoints and writes the table with its provenance;
it takes a minute and never runs the MoM, so a new variant joins the atlas by re-running ``table``
(with the checkpoints; without them, ``run`` first).

``heldout`` runs the MoM at surfaces, angles and a material the atlas does not contain (for
validation/accuracy_atlas.py's held-out check) into its own checkpoint folder (default out/atlas_heldout).
"""
from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))

#: the held-out surfaces (rms slope, sigma_h / lambda), angles and materials: off every grid axis
HELDOUT_SURFACES = ((0.15, 0.3), (0.27, 0.7), (0.42, 1.5), (0.6, 3.0), (0.08, 0.35), (0.27, 2.8))
HELDOUT_THETA_I = (5.0, 25.0, 45.0, 65.0, 75.0)
HELDOUT_MATERIALS = ("PEC", "Al_633nm", "Ag_633nm")
#: the held-out surfaces' seeds start here (the grid's at 10000): no held-out surface reuses a grid draw
HELDOUT_SEED_BASE = 90000


def _executor(args):
    if not args.dask:
        return None
    try:
        from distributed import Client
    except ImportError:
        raise SystemExit("--dask needs the 'distributed' package: pip install 'hyde-bsdf[distributed]'") from None
    return Client(args.dask).get_executor()


def cmd_run(args):
    from hyde_bsdf.mom import atlas

    t0 = time.perf_counter()
    todo = atlas.tasks()
    n = atlas.run_tasks(todo, args.checkpoints, executor=_executor(args), workers=args.workers)
    print(f"ran {n} of {len(todo)} tasks in {time.perf_counter() - t0:.0f} s wall; checkpoints in {args.checkpoints}")
    return 0


def heldout_materials():
    from hyde_bsdf.mom import atlas

    mats = {m.name: m for m in atlas.materials()}
    n, k = atlas._mitsuba_index("Ag", 633.0)
    mats["Ag_633nm"] = atlas.Material("Ag_633nm", n, k, "silver at 633 nm, Mitsuba data/ior Ag (linear)")
    return [mats[name] for name in HELDOUT_MATERIALS]


def cmd_heldout(args):
    from hyde_bsdf.mom import atlas

    mats = heldout_materials()
    grid = atlas.Grid(theta_i_deg=HELDOUT_THETA_I)
    todo = atlas.tasks(grid, mats=mats, surfaces=HELDOUT_SURFACES, seed_base=HELDOUT_SEED_BASE)
    n = atlas.run_tasks(todo, args.checkpoints, executor=_executor(args), workers=args.workers, grid=grid, mats=mats)
    print(f"ran {n} of {len(todo)} held-out tasks; checkpoints in {args.checkpoints}")
    return 0


def cmd_table(args):
    from hyde_bsdf.mom import atlas_errors

    t0 = time.perf_counter()
    path = atlas_errors.write_table(args.checkpoints, args.output)
    print(f"wrote {path} in {time.perf_counter() - t0:.0f} s")
    return 0


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = ap.add_subparsers(dest="command", required=True)
    for name, default in (("run", "out/atlas_runs"), ("heldout", "out/atlas_heldout"), ("table", "out/atlas_runs")):
        p = sub.add_parser(name)
        p.add_argument("--checkpoints", default=default, help=f"checkpoint folder (default {default})")
        if name == "table":
            p.add_argument("-o", "--output", default=str(REPO / "hyde_bsdf" / "data" / "accuracy_atlas.npz"))
        else:
            p.add_argument("--workers", type=int, default=2, help="process-pool workers (default 2)")
            p.add_argument("--dask", metavar="ADDRESS", help="run the tasks on this dask scheduler instead")
    args = ap.parse_args(argv)
    return {"run": cmd_run, "heldout": cmd_heldout, "table": cmd_table}[args.command](args)


if __name__ == "__main__":
    sys.exit(main())
