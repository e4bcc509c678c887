"""A unilateral non-associated relation must push back whichever way its dual points: the
admissible sign of its multiplier comes from its own response (A K⁻¹ D), not from its sense
alone. A stop on the end of a bar, u_end <= 1e-4, whose reaction is a load pattern."""

import numpy as np
import pytest

from helpers.stop_bar import stop_bar


def stop_intensity(t, dual):
    """E A u / L = 1e-4 * 1e3 * 0.1 = 0.01 once the stop is reached: 0.03 t + 0.1 dual λ = 0.01."""
    return np.where(0.3 * t > 0.1 + 1e-12, (0.01 - 0.03 * t) / (0.1 * dual), 0.0)


CASES = {  # pull, dual, value, sense
    "dual pushes back": (0.3, -1.0, 1e-4, "<="),
    "dual points the other way": (0.3, 1.0, 1e-4, "<="),
    "mirror image": (-0.3, 1.0, -1e-4, ">="),
    "mirror, dual the other way": (-0.3, -1.0, -1e-4, ">="),
}


@pytest.mark.parametrize("case", sorted(CASES))
def test_stop_holds_whichever_way_the_dual_points(case, run):
    pull, dual, value, sense = CASES[case]
    res = run(stop_bar(pull, dual, value, sense), name="stop")
    t = res["steps/time"]
    u_end = res["relations/stop/primal"][:, 0]
    np.testing.assert_allclose(u_end, np.sign(pull) * np.minimum(3e-4 * t, 1e-4), rtol=1e-10)
    lam = res["relations/stop/multiplier"][:, 0]
    expected = stop_intensity(t, dual) * np.sign(pull)
    np.testing.assert_allclose(lam, expected, rtol=1e-10, atol=1e-14)
    assert list(res["relations/stop/active"][:, 0]) == [0, 1, 1, 1]


def test_mirror_images_give_mirrored_answers(run):
    a = run(stop_bar(0.3, -1.0, 1e-4, "<="), name="a")
    b = run(stop_bar(-0.3, 1.0, -1e-4, ">="), name="b")
    np.testing.assert_array_equal(a["relations/stop/active"], b["relations/stop/active"])
    # equal and opposite in exact arithmetic; in floating point to the round-off of a solve
    # (MUMPS on several ranks adds contributions in the order messages arrive: the
    # displacement that is zero in exact arithmetic, ~1e-18 here, is not reproducible)
    u = a["fields/displacement"]
    np.testing.assert_allclose(u, -b["fields/displacement"], atol=1e-12 * np.abs(u).max())
    np.testing.assert_allclose(a["relations/stop/multiplier"], b["relations/stop/multiplier"],
                               rtol=1e-12)
