"""Safe selector expressions and geometric selectors."""

import numpy as np
import pytest

from parsolve.errors import InputError
from parsolve.mesh.selectors import box, evaluate, near_point

# a 3 x 3 grid of points on [0, 1]^2, numbered x fastest
P2 = np.array([[x, y] for y in (0.0, 0.5, 1.0) for x in (0.0, 0.5, 1.0)])
P3 = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 2.0], [1.0, 1.0, 2.0]])
TOL = 1e-9


def sel(expr, points=P2, tol=TOL):
    return np.flatnonzero(evaluate(expr, points, tol)).tolist()


def test_equality_uses_tolerance():
    assert sel("x == 0") == [0, 3, 6]
    pts = P2 + np.array([5e-10, 0.0])  # slightly off: still selected with tol 1e-9
    assert sel("x == 0", pts) == [0, 3, 6]
    assert sel("x == 0", pts, tol=1e-12) == []
    assert sel("x != 0") == [1, 2, 4, 5, 7, 8]


def test_inequalities():
    assert sel("x < 0.5") == [0, 3, 6]  # strict
    assert sel("x <= 0.5") == [0, 1, 3, 4, 6, 7]
    assert sel("x <= 0.5 - 1e-10") == [0, 1, 3, 4, 6, 7]  # tol slack
    assert sel("x >= 0.5 + 1e-10") == [1, 2, 4, 5, 7, 8]
    assert sel("x > 0.5") == [2, 5, 8]
    assert sel("0.25 <= x <= 0.75") == [1, 4, 7]  # chained
    assert sel("0 < x < y") == [7]


def test_logic_and_arithmetic():
    assert sel("abs(x - 1) < 1e-9 and y >= 0.5") == [5, 8]
    assert sel("x == 0 or y == 1") == [0, 3, 6, 7, 8]
    assert sel("not x == 0") == [1, 2, 4, 5, 7, 8]
    assert sel("(x == 0) & (y == 0) | (x == 1) & (y == 1)") == [0, 8]
    assert sel("~(x > 0)") == [0, 3, 6]
    assert sel("x**2 + y**2 <= 1.0001") == [0, 1, 2, 3, 4, 6]
    assert sel("sqrt(x*x + y*y) == sqrt(2)/2", tol=1e-12) == [4]
    assert sel("sin(pi*x) == 0 and cos(pi*y) == -1") == [6, 8]
    assert sel("-x / 2 == -0.25") == [1, 4, 7]
    assert sel("True") == list(range(9))
    assert sel("sqrt(abs(x - 1)) == 0") == [2, 5, 8]


def test_z_only_in_3d():
    assert sel("z == 2", P3) == [2, 3]
    assert sel("x == 1 and z > 1", P3) == [3]
    with pytest.raises(InputError, match="'z' does not exist in a 2D mesh"):
        evaluate("z == 0", P2, TOL)


@pytest.mark.parametrize(
    "expr, reason",
    [
        ("__import__('os')", "not allowed"),
        ("x.real", "attribute access"),
        ("open('f')", "not allowed"),
        ("x == 'a'", "numbers only"),
        ("lambda: 1", "lambda"),
        ("t == 0", "unknown name 't'"),
        ("abs(x, y) == 0", "exactly one argument"),
        ("x[0] == 0", "indexing"),
        ("x // 2 == 0", "not allowed"),
        ("x + 1", "not a condition"),
        ("(x == 0) + 1", "condition is used where a number"),
        ("x and y", "number is used where a condition"),
        ("x ==", "syntax error"),
        ("[x for x in ()]", "not allowed"),
        ("x in (1, 2)", "not allowed"),
    ],
)
def test_rejects_unsafe_or_invalid(expr, reason):
    with pytest.raises(InputError, match=reason) as info:
        evaluate(expr, P2, TOL, source="scene.yaml", key="regions.left.where")
    assert info.value.source == "scene.yaml" and info.value.key == "regions.left.where"
    assert str(info.value).startswith("scene.yaml: regions.left.where: invalid selector")


@pytest.mark.parametrize("expr, reason", [
    ("10**10**10 > x", r"10 \*\* 10 \*\* 10 is inf"),          # power tower: no hang, no inf
    ("sqrt(x - 1) == 0", r"sqrt\(x - 1\) is not finite at 6 of 9 points \(e.g. nan at \(0, 0\)\)"),
    ("1/(x-x) > 0", r"1 / \(x - x\) is not finite at 9 of 9 points"),
    ("x < 1e400", "is inf"),
    ("x < 10**400", r"10 \*\* 400 is inf"),
])
def test_non_finite_values_are_errors(expr, reason):
    """Every number a selector computes must be finite at every point, without numpy warnings."""
    import warnings

    with warnings.catch_warnings():
        warnings.simplefilter("error")
        with pytest.raises(InputError, match=reason) as info:
            evaluate(expr, P2, TOL, source="s.toml", key="regions.r")
    assert info.value.key == "regions.r"


def test_value_expressions_must_be_finite():
    from parsolve.mesh.selectors import evaluate_value

    np.testing.assert_allclose(evaluate_value("1e-3 * x + y", P2), 1e-3 * P2[:, 0] + P2[:, 1],
                               rtol=0, atol=0)
    with pytest.raises(InputError, match=r"sqrt\(-1 - x\) is not finite at 9 of 9") as info:
        evaluate_value("sqrt(-1-x)", P2, "s.toml", "relations[0].value")
    assert info.value.oneline().startswith("s.toml: relations[0].value: invalid expression")


def test_box_near():
    assert np.flatnonzero(box([0.0, 0.0], [0.5, 0.5], P2, TOL)).tolist() == [0, 1, 3, 4]
    assert np.flatnonzero(box([0.0, 0.0], [0.5 - 1e-10, 0.5], P2, TOL)).tolist() == [0, 1, 3, 4]
    assert np.flatnonzero(box([0, 0, 1], [1, 1, 3], P3, TOL)).tolist() == [2, 3]
    assert np.flatnonzero(near_point([0.5, 0.5], P2, 0.1)).tolist() == [4]
    assert np.flatnonzero(near_point([0.5, 0.25], P2, 0.25)).tolist() == [1, 4]
    with pytest.raises(InputError, match="2 coordinates"):
        near_point([0.0, 0.0, 0.0], P2, 0.1)
    with pytest.raises(InputError, match="exceeds"):
        box([1.0, 0.0], [0.0, 1.0], P2, TOL)
