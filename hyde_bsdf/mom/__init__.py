"""Method-of-moments reference for 1-D random rough surfaces, and the model reduced to 1-D.

``solver`` (:func:`scatter`: Gaussian surfaces, partitions, executors, both polarisations, a PEC
or a finite index n - jk, the Mueller elements and the energy checks, in stages), one module per
solution method -- ``dense`` (LU of the full matrix) and ``fast`` (forward-backward sweeps with
spectral acceleration for long partitions and grazing incidence, GMRES and dense fallbacks) --,
``kernels`` (the single- and double-layer operators of the two-region integral equations, far
field, absorbed power), ``gather`` (waiting on an executor with liveness checks and a timeout: a
dead dask cluster ends in one error, never a hang) and ``model1d`` (the pBRDF of a 1-D facet
surface with V-groove, Smith or no shadowing, the apples-to-apples counterpart of the MoM result).
"""
from hyde_bsdf.mom.solver import *  # noqa: F401,F403  (the public names of the solver)
from hyde_bsdf.mom.solver import __all__ as _solver_all

__all__ = list(_solver_all)
