"""A control beyond what a perfectly plastic body carries fails naming its limit load.

A bar 1 × 0.2 × 0.2 of a von Mises material without hardening (σ_y = 250), one hexahedron
across, pulled on its end x = 1 by a load whose intensity is the multiplier of a control on the
mean u_x of its other end x = 0, which rests on four springs k = 1e4 along x (one per node).
The stress is uniaxial and uniform, so the bar's limit load is σ_y A = 250 × 0.04 = 10, and the
springs' elongation, F / 4k, cannot pass 2.5e-4. The scene's single step asks for 4e-4 (a load of
16): cut in halves the run reaches 2.5e-4 at t = 0.625 with the load 10, where every later
attempt fails on a singular solve; the failure (exit 3) names the limit load, the target and the
way out. The limit is checked independently by load-controlled runs (a load just below 10
converges, one just above does not), and with hardening the same control completes."""

import pytest

from helpers.scene import scene

from parsolve.errors import SolverError

SIGMA_Y, AREA, K = 250.0, 0.2 * 0.2, 1e4
LIMIT = SIGMA_Y * AREA
TARGET = 4e-4

BAR = {
    "mesh": {"generator": "box", "lx": 1.0, "ly": 0.2, "lz": 0.2, "nx": 4, "ny": 1, "nz": 1,
             "cell": "hexahedron"},
    "model": {"hypothesis": "3d"},
    "materials": [{"model": "von_mises", "E": 200e3, "nu": 0.3, "sigma_y": SIGMA_Y, "H": 0.0}],
    "loads": [{"name": "pull", "region": "xmax", "total_force": [1.0, 0.0, 0.0]}],
    "springs": [{"region": "xmin", "stiffness": [K, 0.0, 0.0]}],
    "relations": [
        {"name": "sym_y", "type": "dirichlet", "region": "ymin", "components": ["y"]},
        {"name": "sym_z", "type": "dirichlet", "region": "zmin", "components": ["z"]},
        {"name": "drive", "type": "mean", "region": "xmin", "component": "x",
         "value": TARGET, "dual": "pull"}],
    "steps": {"count": 1},
}


def test_the_limit_load_is_named(run):
    with pytest.raises(SolverError) as info:
        run(scene(BAR), name="limit")
    message = str(info.value)
    reached = LIMIT / (4 * K)
    assert message.startswith("control 'drive' can no longer reach its value: ")
    assert f"where it reached {reached:.6g} (t = 0.625) with a control load of {LIMIT:.6g}" \
        in message
    assert f"carries no more than its limit load, {LIMIT:.6g} (" in message
    assert "perfectly plastic cells (von Mises, H = 0) form a mechanism" in message
    assert "control a quantity that grows as the body flows" in message


@pytest.mark.parametrize("force, passes", [(LIMIT * (1 - 1e-6), True),
                                           (LIMIT * (1 + 1e-3), False)])
def test_the_limit_load_by_load_control(run, force, passes):
    """The same bar pulled by a given force, held at x = 0 by the springs alone."""
    text = scene(BAR, relations=BAR["relations"][:2],
                 loads=[{"name": "pull", "region": "xmax", "total_force": [force, 0.0, 0.0]}])
    if passes:
        res = run(text, name="below")
        assert res["attrs"]["status"] == "complete"
        return
    with pytest.raises(SolverError):
        run(text, name="above")


def test_with_hardening_the_target_is_reached(run):
    hardening = dict(BAR["materials"][0], H=2e3)
    res = run(scene(BAR, materials=[hardening]), name="hardening")
    assert res["attrs"]["status"] == "complete"
    assert res["relations/drive/primal"][-1, 0] == pytest.approx(TARGET, rel=1e-9)
    # the springs carry the control load: F = 4 k u
    assert res["relations/drive/multiplier"][-1, 0] == pytest.approx(4 * K * TARGET, rel=1e-9)
