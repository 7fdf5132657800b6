"""The accuracy atlas's MoM runs: a grid of 1-D rough surfaces and materials, checkpointed (issue 32).

What
----
The atlas (:mod:`hyde_bsdf.model.accuracy` reads it) states, per incidence angle, rms slope, surface
height and material, how far each model variant (shadowing x diffuse, as the 1-D reduction
:mod:`hyde_bsdf.mom.model1d` computes it) lies from exact EM.  This module makes the exact half: one
MoM run (:func:`hyde_bsdf.mom.scatter`, both polarisations) per surface and material, whose
per-partition far fields are kept (:func:`run_task`), so that every statistic of the comparison --
:mod:`hyde_bsdf.mom.atlas_errors` -- and every model variant added later is computed from the
checkpoints without running the MoM again.

The grid (:data:`GRID`)
-----------------------
* incidence 0-85 deg (10 angles, all in one run: the fast solver sweeps them together; the Gaussian
  beam lights 80 and 85 deg, the windowed current of Eq. 22 the others -- ``incidence="auto"``);
* rms slope 0.05-0.7 and sigma_h / lambda 0.1-4 (6 x 6; the correlation length ell = sqrt(2) sigma_h /
  slope runs from 0.2 lambda to 113 lambda);
* PEC, aluminium at 633 nm and 1550 nm, gold at 633 nm (Mitsuba's ``data/ior`` where it has them; its
  Al table ends at 886 nm, so 1550 nm takes the issue's n = 1.5, k = 15, as in the literature's
  n ~ 1.4-1.6, k ~ 15-16), glass n = 1.5.  The same surface realisation (seed per surface) serves every material.

The MoM settings (:func:`plan`): partitions of max(300 lambda, 10 ell) with the default taper w = L/4
(75 lambda: Thorsos' parameter 6e-4 at 70 deg; the beam's spectral spread 1.4 deg at 85 deg),
10 points per wavelength (15 from rms slope 0.5 on; more where the solver resamples a steep or
curved realisation), up to :data:`PARTITIONS` = 8 partitions.  A pilot partition is timed first;
where 8 partitions would cost more than :data:`TASK_CPU_CAP_S` CPU seconds, fewer are run (at least
:data:`MIN_PARTITIONS` = 2), and a surface whose two partitions cost more than 1.5 x the cap is
recorded as too costly ("unknown" in the atlas): the tiny correlation lengths (ell < 0.5 lambda,
where the solver needs 50-100 points per wavelength to follow the curvature) on metals.

Checkpoints: one compressed ``.npz`` per finished task in a folder, written atomically as the task
finishes (:func:`run_tasks`); a rerun skips the tasks whose file exists and was made with the same
grid (``spec.json``), so a killed generation resumes where it stopped.  Tasks run on any
``concurrent.futures`` executor (a process pool, or ``distributed.Client(...).get_executor()``),
each one in a single process.
"""
from __future__ import annotations

import json
import math
import time
import warnings
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from hyde_bsdf.errors import UsageError
from hyde_bsdf.io.atomic import atomic_path
from hyde_bsdf.mom.gather import end_pool, gather
from hyde_bsdf.progress import as_callback

__all__ = ["Material", "Grid", "GRID", "MATERIALS", "plan", "tasks", "run_task", "run_tasks", "load_checkpoints",
           "PARTITIONS", "MIN_PARTITIONS", "TASK_CPU_CAP_S"]

#: partitions per surface and material (fewer where the pilot says they would cost more than the cap)
PARTITIONS = 8
#: fewest partitions of a run: the spread between partitions is the MoM's statistical error
MIN_PARTITIONS = 2
#: CPU seconds one surface and material may cost (estimated from the pilot partition)
TASK_CPU_CAP_S = 60.0
#: shortest partition (wavelengths) and the least correlation lengths per partition
PARTITION_WL = 300.0
ELLS_PER_PARTITION = 10.0
#: from this rms slope on, 15 points per wavelength (the steep flanks; the solver resamples further as needed)
STEEP_SLOPE = 0.5


@dataclass(frozen=True)
class Material:
    """An atlas material: ``name``, the paper's eta = n - jk (None, None: a PEC) and where n, k come from."""

    name: str
    n: float | None
    k: float | None
    source: str


def _mitsuba_index(name, wavelength_nm):
    """(n, k) of Mitsuba's ``data/ior`` table ``name`` at ``wavelength_nm``, linear as Mitsuba interpolates."""
    from hyde_bsdf.io.ior import material_files

    out = []
    for path in material_files(name):
        data = np.loadtxt(path, comments="#")
        out.append(round(float(np.interp(wavelength_nm, data[:, 0], data[:, 1])), 4))
    return tuple(out)


def materials():
    """The atlas's materials; Al and Au at 633 nm read from Mitsuba's tables (UsageError without Mitsuba)."""
    al = _mitsuba_index("Al", 633.0)
    au = _mitsuba_index("Au", 633.0)
    return (Material("PEC", None, None, "perfect electric conductor"),
            Material("Al_1550nm", 1.5, 15.0, "aluminium near 1550 nm: n = 1.5, k = 15, the issue's value (the "
                     "literature has n ~ 1.4-1.6, k ~ 15-16 there, e.g. Rakic et al., Appl. Opt. 37, 5271 (1998); "
                     "Mitsuba's Al table ends at 886 nm)"),
            Material("Al_633nm", al[0], al[1], "aluminium at 633 nm, Mitsuba data/ior Al (linear)"),
            Material("Au_633nm", au[0], au[1], "gold at 633 nm, Mitsuba data/ior Au (linear)"),
            Material("glass", 1.5, 0.0, "glass, n = 1.5"))


#: the materials' names in the atlas's order (conductors from the PEC towards the smallest |eta|, then glass)
MATERIALS = ("PEC", "Al_1550nm", "Al_633nm", "Au_633nm", "glass")


@dataclass(frozen=True)
class Grid:
    """The atlas's axes: incidence and observation angles (degrees), rms slopes, heights sigma_h / lambda."""

    theta_i_deg: tuple = (0.0, 10.0, 20.0, 30.0, 40.0, 50.0, 60.0, 70.0, 80.0, 85.0)
    theta_r_step_deg: float = 0.5
    rms_slopes: tuple = (0.05, 0.1, 0.2, 0.35, 0.5, 0.7)
    heights_wl: tuple = (0.1, 0.2, 0.5, 1.0, 2.0, 4.0)
    partitions: int = PARTITIONS
    min_partitions: int = MIN_PARTITIONS
    task_cpu_cap_s: float = TASK_CPU_CAP_S

    def theta_r_deg(self):
        """Observation angles, signed (+ = specular side), every ``theta_r_step_deg`` short of grazing."""
        half = 90.0 - self.theta_r_step_deg / 2.0
        return np.linspace(-half, half, int(round(2 * half / self.theta_r_step_deg)) + 1)


GRID = Grid()


def plan(rms_slope, height_wl, index=0, seed_base=10000):
    """The MoM settings of one surface: correlation length, partition length, points per wavelength, seed."""
    ell = math.sqrt(2.0) * height_wl / rms_slope
    partition = max(PARTITION_WL, math.ceil(ELLS_PER_PARTITION * ell))
    # the spectrum needs > 3.9 / ell points per wavelength and check_sampling 5 per ell; steep surfaces 15
    ppw = max(10.0 if rms_slope < STEEP_SLOPE else 15.0, math.ceil(6.0 / ell))
    # seeds 100 apart: the pilot takes seed, the other partitions seed + 1 (no surface shares a draw)
    return dict(corr_length_wl=ell, partition_wl=float(partition), pts_per_wl=float(ppw), seed=seed_base + 100 * index)


def _cost_rank(task):
    """A rough relative cost, to run the cheap tasks (early checkpoints) first."""
    per_unknown = {"PEC": 1.0, "glass": 4.0}.get(task["material"], 6.0)
    curvature = max(1.0, 3.0 * task["rms_slope"] / task["corr_length_wl"])
    return per_unknown * task["partition_wl"] * task["pts_per_wl"] * curvature


def tasks(grid=GRID, mats=None, surfaces=None, theta_i_deg=None, seed_base=10000):
    """One task (a dict) per surface and material, cheapest first; ``surfaces``: (rms_slope, height) pairs
    (default the grid's), ``mats``: Material records (default :func:`materials`); ``seed_base``: the first
    surface's seed (held-out runs take another base, so that no surface reuses the grid's draws)."""
    mats = materials() if mats is None else mats
    pairs = [(s, h) for s in grid.rms_slopes for h in grid.heights_wl] if surfaces is None else list(surfaces)
    out = []
    for i, (slope, height) in enumerate(pairs):
        p = plan(slope, height, i, seed_base)
        for m in mats:
            out.append(dict(key=f"s{slope:g}_h{height:g}_{m.name}", rms_slope=float(slope), height_wl=float(height),
                            material=m.name, n=m.n, k=m.k, theta_i_deg=list(theta_i_deg or grid.theta_i_deg),
                            theta_r_step_deg=grid.theta_r_step_deg, partitions=grid.partitions,
                            min_partitions=grid.min_partitions, cap_s=grid.task_cpu_cap_s, **p))
    return sorted(out, key=_cost_rank)


def _scatter(task, partitions, seed):
    """One MoM call of ``partitions`` partitions of the task's surface (warnings recorded, not raised)."""
    from hyde_bsdf.mom.solver import SerialExecutor, scatter

    theta_r = Grid(theta_r_step_deg=task["theta_r_step_deg"]).theta_r_deg()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")          # every reason is in res.warnings, kept in the checkpoint
        return scatter(task["partition_wl"] * partitions, partitions, task["height_wl"], task["corr_length_wl"],
                       task["theta_i_deg"], theta_r, pts_per_wl=task["pts_per_wl"], seed=seed,
                       executor=SerialExecutor(), polarization=("s", "p"), n=task["n"], k=task["k"],
                       progress=False)


def _cpu(res):
    t = res.times
    return float(t["fill"] + t["factor"] + t["solve"] + t["far_field"])


def run_task(task):
    """The MoM for one surface and material: a timed pilot partition, then as many more as the cap allows.

    Returns a dict of arrays and numbers (what :func:`run_tasks` checkpoints): ``F_s``, ``F_p`` [M, n_ti, n_tr]
    (the partitions' far fields, :attr:`MoMResult.partition_fields`), ``valid`` [n_ti, n_tr] (both
    polarisations clear of the partition's floor), ``energy`` [2, n_ti] (reflected + absorbed, s and p, the
    runs' worst), ``coherent`` [n_ti] (coherent share of the reflected power, s), the CPU seconds, unknowns
    per partition, solver, warnings; or ``status`` "too_costly" with the pilot's cost.
    """
    t0 = time.perf_counter()
    pilot = _scatter(task, 1, task["seed"])
    per_partition = max(_cpu(pilot), 1e-3)
    base = dict(key=task["key"], task=json.dumps(task), cpu_per_partition=per_partition,
                unknowns=int(pilot.params["unknowns_per_partition"]), solver=str(pilot.params["solver"]),
                pts_per_wl_used=float(pilot.params["pts_per_wl"]))
    if task["min_partitions"] * per_partition > 1.5 * task["cap_s"]:
        return dict(base, status="too_costly", partitions=1, cpu_s=per_partition, wall_s=time.perf_counter() - t0)
    more = int(min(task["partitions"], max(task["min_partitions"], task["cap_s"] // per_partition))) - 1
    rest = _scatter(task, more, task["seed"] + 1)
    runs = (pilot, rest)
    fields = {p: np.concatenate([r.partition_fields[p] for r in runs]).astype(np.complex64) for p in "sp"}
    energy = np.stack([np.where(np.abs(pilot.energy_s - 1) > np.abs(rest.energy_s - 1), pilot.energy_s, rest.energy_s),
                       np.where(np.abs(pilot.energy_p - 1) > np.abs(rest.energy_p - 1), pilot.energy_p, rest.energy_p)])
    weights = np.array([1.0, more]) / (1.0 + more)
    coherent = sum(w * r.power_coherent / r.power_balance_nominal for w, r in zip(weights, runs))
    stage = ("fill", "factor", "solve", "far_field")
    times = np.array([[r.times[s] for s in stage] for r in runs])     # CPU s per stage: pilot, the others
    return dict(base, status="ok", F_s=fields["s"], F_p=fields["p"], partitions=1 + more, times=times,
                valid=pilot.valid_s & pilot.valid_p & rest.valid_s & rest.valid_p, energy=energy,
                coherent=coherent, cpu_s=_cpu(pilot) + _cpu(rest), wall_s=time.perf_counter() - t0,
                incidence=json.dumps(pilot.params["incidence"]), taper_width_wl=float(pilot.params["taper_width_wl"]),
                warnings=json.dumps(sorted(set(pilot.warnings + rest.warnings))))


def _spec(grid, mats):
    return {"grid": asdict(grid), "materials": [asdict(m) for m in mats], "partition_wl": PARTITION_WL,
            "ells_per_partition": ELLS_PER_PARTITION}


def _check_folder(folder, spec):
    """The checkpoint folder, created with ``spec.json``; a folder made for another grid is refused."""
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / "spec.json"
    if path.exists():
        old = json.loads(path.read_text(encoding="utf-8"))
        if old != json.loads(json.dumps(spec)):
            raise UsageError(f"checkpoint folder {str(folder)!r} holds runs of another grid (spec.json differs): "
                             "give a new folder, or remove it to start over")
    else:
        with atomic_path(path) as tmp:
            Path(tmp).write_text(json.dumps(spec, indent=1), encoding="utf-8")
    return folder


def _save(folder, result):
    arrays = {k: (np.asarray(v) if not isinstance(v, str) else np.array(v)) for k, v in result.items()}
    with atomic_path(folder / f"{result['key']}.npz") as tmp:
        with open(tmp, "wb") as fh:
            np.savez_compressed(fh, **arrays)


def run_tasks(todo, folder, executor=None, workers=2, progress=True, grid=GRID, mats=None):
    """Run the tasks not yet in ``folder`` on ``executor`` (None: a process pool of ``workers``), checkpointing
    each as it finishes; returns the number run.  ``progress``: a callback, True (stderr lines) or False."""
    from hyde_bsdf.mom.solver import process_pool

    mats = materials() if mats is None else mats
    folder = _check_folder(folder, _spec(grid, mats))
    todo = [t for t in todo if not (folder / f"{t['key']}.npz").exists()]
    report = as_callback(progress, prefix="atlas:")
    if not todo:
        return 0
    t0 = time.perf_counter()
    own = executor is None
    ex = process_pool(workers) if own else executor

    def done(i, result):
        _save(folder, result)
        if report:
            report(f"{result['key']}: {result['status']}, {result['partitions']} partition(s), "
                   f"{result['cpu_s']:.0f} CPU s ({time.perf_counter() - t0:.0f} s elapsed)")

    finished = False
    try:
        gather(ex, run_task, todo, on_result=done, heartbeat=as_callback(progress, prefix=""), what="task",
               label="atlas")
        finished = True
    finally:
        if own:          # after a failure, no wait for a running task: its worker is ended
            end_pool(ex, finished)
    return len(todo)


def load_checkpoints(folder):
    """{key: dict of arrays} of every checkpoint in ``folder`` (strings back as str)."""
    out = {}
    for path in sorted(Path(folder).glob("*.npz")):
        with np.load(path, allow_pickle=False) as data:
            out[path.stem] = {k: (str(data[k]) if data[k].dtype.kind == "U" else data[k]) for k in data.files}
    return out
