"""/timings/contact: the seconds of the Newton's contact hooks (begin_step, refresh) per step,
beside the other phases; absent from a scene without contact."""

from __future__ import annotations

import numpy as np

from helpers.scene import DROP, scene, shipped


def test_contact_hooks_timed_per_step(run):
    res = run(scene(shipped("contact_block_friction.toml"), output=DROP))
    nsteps = res["steps/time"].size
    assert nsteps == 10
    for phase in ("assembly", "factorization", "solve", "contact", "output", "total"):
        assert res[f"timings/{phase}"].shape == (nsteps,)
    contact = res["timings/contact"]
    assert np.all(contact > 0.0)   # every step begins and refreshes its friction states
    assert np.all(contact <= res["timings/total"])
    # every assembly of a step is counted (not the last one alone), and no more than the step
    assert np.all(res["timings/assembly"] > 0) and np.all(res["timings/assembly"] <= res["timings/total"])


def test_no_contact_no_contact_timing(run):
    res = run(scene(shipped("springs_bar_supports.toml"), output=DROP))
    assert "timings/total" in res and "timings/contact" not in res
