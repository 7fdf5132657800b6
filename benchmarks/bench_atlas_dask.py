"""The accuracy atlas's generation over executors: wall time and speed-up of dask workers (issue 32).

Runs the same subset of the atlas's MoM tasks (hyde_bsdf/mom/atlas.py; default the 6 cheapest, PEC) into
fresh checkpoint folders on: one process (a process pool of 1), a dask LocalCluster of 1 and of 2 worker
processes, and a process pool of 2; prints each one's wall time, the CPU seconds its tasks report, and the
speed-up over one process.  The speed-up is bounded by the cores the machine gives the run (CPU seconds /
wall seconds is printed as "cores used"): on a loaded shared machine it says as much about the load as
about dask.

    .venv/bin/python benchmarks/bench_atlas_dask.py [--tasks 6]
"""
from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))


def _run(todo, executor, workers, folder):
    from hyde_bsdf.mom import atlas

    t0 = time.perf_counter()
    atlas.run_tasks(todo, folder, executor=executor, workers=workers, progress=False)
    wall = time.perf_counter() - t0
    cpu = sum(float(c["cpu_s"]) for c in atlas.load_checkpoints(folder).values())
    return wall, cpu


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--tasks", type=int, default=6, help="how many of the cheapest tasks (default 6)")
    args = ap.parse_args(argv)
    # the workers' sampling profiler (a thread every 10 ms) runs inside each task's process and would be counted in
    # its CPU seconds (time.process_time counts every thread): off, as on a cluster that runs long tasks
    os.environ.setdefault("DASK_DISTRIBUTED__WORKER__PROFILE__ENABLED", "False")
    import dask
    from distributed import Client, LocalCluster

    # dask starts its workers with MALLOC_TRIM_THRESHOLD_=65536, which turns off glibc's dynamic mmap threshold: every
    # large NumPy array of the MoM is then mapped and page-faulted anew, 2.2x the CPU of the same task in a process
    # pool (measured: 41.5 against 18.4 CPU s for these 6 tasks).  Keep dask's thread settings, drop that one.
    environ = dict(dask.config.get("distributed.nanny.pre-spawn-environ", {}))
    environ.pop("MALLOC_TRIM_THRESHOLD_", None)
    dask.config.set({"distributed.nanny.pre-spawn-environ": environ})

    from hyde_bsdf.mom import atlas

    todo = atlas.tasks(mats=[m for m in atlas.materials() if m.name == "PEC"])[:args.tasks]
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for label, kind, workers in (("process pool, 1 worker", "pool", 1), ("dask, 1 worker", "dask", 1),
                                     ("dask, 2 workers", "dask", 2), ("process pool, 2 workers", "pool", 2)):
            folder = os.path.join(tmp, label.replace(" ", "_").replace(",", ""))
            if kind == "pool":
                wall, cpu = _run(todo, None, workers, folder)
            else:
                with LocalCluster(n_workers=workers, threads_per_worker=1, processes=True, dashboard_address=None) \
                        as cluster, Client(cluster) as client:
                    wall, cpu = _run(todo, client.get_executor(), workers, folder)
            rows.append((label, wall, cpu))
            print(f"{label:26s} wall {wall:7.1f} s   task CPU {cpu:6.1f} s   cores used {cpu / wall:4.2f}", flush=True)
    base = rows[0][1]
    for label, wall, _ in rows[1:]:
        print(f"speed-up of {label} over one process: {base / wall:.2f}")
    print(f"({len(todo)} tasks: {', '.join(t['key'] for t in todo)}; load average {os.getloadavg()[0]:.1f} at the end)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
