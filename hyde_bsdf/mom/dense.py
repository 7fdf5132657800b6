"""Dense MoM solver: the full N x N matrices of :mod:`hyde_bsdf.mom.kernels`, one LU per polarisation.

The reference path of :func:`hyde_bsdf.mom.scatter` (``solver="dense"``): exact to
round-off for the discretised equations, O(N^2) memory and O(N^3) time, so it is
refused above ``MAX_UNKNOWNS`` per partition (:mod:`hyde_bsdf.mom.solver`).

PEC: the EFIE S0 v = psi (s) or the MFIE (1/2 - D0) u = psi (p).  Finite index: the
interior equation is solved first, u = rho Zt v with Zt = (1/2 + D1)^-1 S1 (banded in a
metal, whose Green's function dies within a few skin depths), leaving one N x N system
(rho (1/2 - D0) Zt + S0) v = psi per polarisation.  All incidence angles are right-hand
sides of one LU.
"""
from __future__ import annotations

import time

import numpy as np
import scipy.linalg

from hyde_bsdf.errors import UsageError

from hyde_bsdf.mom.kernels import K0, layer_matrices

__all__ = ["solve_dense", "check_finite_surface"]


def _banded_solve(A, B, band):
    """Solve A X = B for a banded A (``band`` off-diagonals each side), B dense [N, N]."""
    n = A.shape[0]
    ab = np.zeros((2 * band + 1, n), dtype=A.dtype)
    for d in range(-band, band + 1):
        # LAPACK band storage: ab[band + i - j, j] = A[i, j]
        diag = np.diagonal(A, offset=-d)
        if d >= 0:
            ab[band + d, : n - d] = diag
        else:
            ab[band + d, -d:] = diag
    return scipy.linalg.solve_banded((band, band), ab, B, check_finite=False)


def _band_sparse(A, band):
    """The entries of A within ``band`` of the diagonal, as a CSR matrix."""
    import scipy.sparse
    n = A.shape[0]
    offsets = list(range(-band, band + 1))
    diags = [np.diagonal(A, offset=d) for d in offsets]
    return scipy.sparse.diags(diags, offsets, shape=(n, n), format="csr")


def check_finite_surface(x, y, fp, fpp, psi) -> None:
    """UsageError unless the surface profile (x, y, y', y'') and the incident field are finite: a NaN
    there would come out as NaN fields, silently."""
    for name, a in (("x", x), ("the height y", y), ("the slope y'", fp), ("the curvature y''", fpp),
                    ("the incident field", psi)):
        bad = ~np.isfinite(np.asarray(a))
        if bad.any():
            raise UsageError(f"the surface profile has {int(bad.sum())} NaN or infinite value(s) in {name} (first "
                             f"at index {int(np.argmax(bad.ravel()))}); a MoM solve needs a finite surface")


def solve_dense(x, y, fp, fpp, dx, psi, pols, eta, clock=time.process_time):
    """Surface fields u, v of one partition by dense LU.

    x, y, fp, fpp : ndarray [N] (local coordinates, wavelengths); psi : [N, n_ti] incident
    field; pols : tuple of "s"/"p"; eta : None (PEC) or n - j kappa.
    Returns a dict with ``u_P``, ``v_P`` [N, n_ti] per polarisation (None where zero: a PEC)
    and ``times`` = (fill, factor, solve) in ``clock`` seconds.
    """
    check_finite_surface(x, y, fp, fpp, psi)
    t0 = clock()
    n = x.size
    half = 0.5 * np.eye(n)
    S0, D0, _ = layer_matrices(x, y, fp, fpp, dx, K0, need_S=(eta is not None or "s" in pols),
                               need_D=(eta is not None or "p" in pols))
    systems = {}
    if eta is None:
        if "s" in pols:
            systems["s"] = S0            # EFIE (u = 0):  S0 v = psi
        if "p" in pols:
            D0 *= -1.0
            D0 += half                   # MFIE (v = 0):  (1/2 - D0) u = psi
            systems["p"] = D0
        Zt = P = None
    else:
        S1, D1, band = layer_matrices(x, y, fp, fpp, dx, K0 * eta)
        D1 += half
        # interior equation: u = rho Zt v with Zt = (1/2 + D1)^-1 S1 (banded in a metal)
        banded = 4 * band < n
        Zt = _banded_solve(D1, S1, band) if banded else scipy.linalg.solve(D1, S1, check_finite=False)
        del S1, D1
        D0 *= -1.0
        D0 += half
        if banded:
            # Zt decays like the metal's Green's function: keep 3 bands (the rest is < e^-80 of its diagonal)
            Zt = _band_sparse(Zt, 3 * band)
            P = (Zt.T @ D0.T).T          # (1/2 - D0) Zt at the cost of a banded product
        else:
            P = D0 @ Zt                  # (1/2 - D0) Zt
        del D0
        for pol in pols:
            rho = 1.0 if pol == "s" else eta * eta  # d psi_1/dn = rho d psi/dn (p: eps_1 / eps_0)
            systems[pol] = rho * P + S0
    t1 = clock()
    out = {}
    t_factor = t_solve = 0.0
    for pol in pols:
        ta = clock()
        # factor A^T: its transpose view is Fortran-ordered, so LAPACK works in place (no copy)
        # and lu_solve(..., trans=1) solves (A^T)^T X = A X = psi
        lu = scipy.linalg.lu_factor(systems.pop(pol).T, overwrite_a=True, check_finite=False)
        tb = clock()
        sol = scipy.linalg.lu_solve(lu, psi, trans=1, check_finite=False)
        del lu
        if eta is None:
            out["u_" + pol], out["v_" + pol] = (None, sol) if pol == "s" else (sol, None)
        else:
            rho = 1.0 if pol == "s" else eta * eta
            out["u_" + pol], out["v_" + pol] = rho * (Zt @ sol), sol    # (dense or sparse)
        t_factor += tb - ta
        t_solve += clock() - tb
    out["times"] = (t1 - t0, t_factor, t_solve)
    return out
