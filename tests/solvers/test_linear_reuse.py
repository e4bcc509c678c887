"""The direct solver's MUMPS analysis is done once per run: Newton rewrites the operator's
values in place (same pattern), so PCSetUp factors numerically only (SAME_NONZERO_PATTERN).
Counted by PETSc's log events on this process (every rank factors the same number of times):
one symbolic factorization, one numeric per linear solve (per global iteration)."""

from __future__ import annotations

import numpy as np
import pytest
from petsc4py import PETSc

from helpers.scene import DROP, scene, shipped

EVENTS = {"lu": ("MatLUFactorSym", "MatLUFactorNum"),
          "cholesky": ("MatCholFctrSym", "MatCholFctrNum")}


def _counts(kind: str) -> tuple[int, int]:
    return tuple(int(PETSc.Log.Event(name).getPerfInfo()["count"]) for name in EVENTS[kind])


@pytest.mark.petsc_events
@pytest.mark.parametrize("config, kind", [("contact_friction_3d.toml", "lu"),
                                          ("contact_hertz_cylinder.toml", "cholesky")])
def test_one_analysis_per_run(run, config, kind):
    """Frictional 3D box (non-associated: LU), 8 steps; frictionless Hertz (symmetric:
    Cholesky): one analysis, as many numeric factorizations as global iterations (no step
    is cut in these runs)."""
    before = _counts(kind)
    res = run(scene(shipped(config), output=DROP))
    analyses, numeric = np.subtract(_counts(kind), before)
    assert res["attrs"]["status"] == "complete"
    assert int(np.sum(res.get("steps/cuts", 0))) == 0
    assert analyses == 1
    assert numeric == int(res["steps/iterations"].sum())
