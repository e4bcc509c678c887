"""A step's numbers checked before they are written: a non-finite value is a solver failure
(exit 3) on every path — linear, Newton, arc-length, transient — never a "complete" file."""

from __future__ import annotations

import numpy as np
from mpi4py import MPI

from parsolve.errors import SolverError


def check_finite(comm, step: int, t: float, q, multipliers: dict, residual: float, fields: dict,
                 cell_fields: dict, rel_out: dict, extra: dict) -> None:
    """SolverError (on every rank) naming the first non-finite part of a step before it is
    written: the solution, the multipliers, the residual, the cell fields (stresses, material
    states) must be finite; the other outputs may not be NaN (a gap is +inf where no facet
    faced the node yet). Collective."""
    parts = [("solution", [q], np.isfinite),
             ("multipliers", multipliers.values(), np.isfinite),
             ("residual", [residual], np.isfinite),
             ("cell fields (stresses, material states)", cell_fields.values(), np.isfinite),
             ("nodal outputs", fields.values(), _not_nan),
             ("relation outputs", [v for r in rel_out.values() for v in r.values()], _not_nan),
             ("step outputs", extra.values(), _not_nan)]
    local = np.array([not all(ok(_values(a)).all() for a in arrays) for _, arrays, ok in parts],
                     dtype=np.int64)
    anywhere = np.zeros_like(local)
    comm.Allreduce(local, anywhere, op=MPI.MAX)
    bad = np.flatnonzero(anywhere)
    if bad.size:
        raise SolverError(f"non-finite values in the {parts[bad[0]][0]} at step {step} "
                          f"(t = {t:.6g}): not written (a diverged solve, or a material or an "
                          "output that cannot be evaluated there)")


def _values(a) -> np.ndarray:
    """The numbers of an output (an ``OwnedRows``, an array, a scalar); integers are finite."""
    a = np.asarray(getattr(a, "values", a))
    return a.astype(float) if a.dtype.kind in "fc" else np.zeros(0)


def _not_nan(a: np.ndarray) -> np.ndarray:
    return ~np.isnan(a)
