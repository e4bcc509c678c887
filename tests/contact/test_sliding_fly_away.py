"""Finite sliding with 3D mortar rows: a Newton iterate that carries the whole slave surface
off the master leaves no mortar row to make again. That is a failed iteration (the step is cut
and retried), not a crash: the run completes with the cut counted and the answer of the run
that never saw it (1, 2 and 3 ranks)."""

import numpy as np

from parsolve.effects.contact_sliding import FiniteSliding

from test_finite_sliding_3d import BASE, BLOCK, block_scene, check_contact, write_mesh

FLY_AT = 12   # from this call of the repair on, the first iterate (not a step's start) flies


def test_a_flown_iterate_is_a_cut_step(run, shared_tmp, monkeypatch):
    mesh = write_mesh(shared_tmp / "ring_base.msh", BASE, BLOCK)
    text = block_scene(mesh, "mortar").replace("count = 12", "count = 4")
    plain = run(text, name="fly_plain")
    calls = {"n": 0, "flown": 0}
    repair = FiniteSliding._repair_mortar

    def flown(self, x, start=False):
        calls["n"] += 1
        if calls["n"] >= FLY_AT and not start and not calls["flown"]:
            calls["flown"] += 1
            x = x.copy()
            x[np.unique(self.span.slave_facets)] += [0.0, 0.0, 5.0]   # the die 5 above
        return repair(self, x, start)
    monkeypatch.setattr(FiniteSliding, "_repair_mortar", flown)
    res = run(text, name="fly_cut")
    assert calls["flown"] == 1
    assert res["attrs"]["status"] == "complete"
    cuts = res["steps/cuts"]
    assert cuts.sum() == 1, cuts
    # the cut step's halfway point is saved too: the scene's steps are the others
    scene_steps = np.isin(res["steps/time"], plain["steps/time"])
    assert scene_steps.sum() == len(plain["steps/time"]) == len(res["steps/time"]) - 1
    check_contact(res, "slide", ("ground", "drag", "side", "press", "ring"))
    u, u0 = res["fields/displacement"][scene_steps], plain["fields/displacement"]
    np.testing.assert_allclose(u, u0, rtol=0, atol=1e-8 * np.abs(u0).max())

