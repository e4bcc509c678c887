"""Derived stresses of an axisymmetric result: the hoop stress (4th component) is the third
principal direction of the tensor (von Mises and principal values include it)."""

from __future__ import annotations

import numpy as np

from parsolve.post.derive import full_tensor, principal, von_mises


def test_hoop_stress_enters_the_tensor():
    sig = np.array([[1.0, 0.0, 0.0, -1.0], [2.0, 3.0, 0.5, 7.0]])   # (rr, zz, rz, θθ)
    T = full_tensor(sig, 2)
    assert T[0, 2, 2] == -1.0 and T[1, 2, 2] == 7.0 and T[1, 0, 1] == T[1, 1, 0] == 0.5
    # deviator diag(1, 0, -1): sqrt(3/2 · 2) = sqrt(3)
    assert abs(von_mises(T)[0] - np.sqrt(3.0)) < 1e-15
    assert np.allclose(principal(T)[0], [1.0, 0.0, -1.0], atol=1e-15)
    # the plane (xx, yy, xy) layout is unchanged: σzz from the argument
    plane = full_tensor(sig[:, :3], 2, szz=np.array([5.0, 6.0]))
    assert plane[0, 2, 2] == 5.0 and plane[1, 2, 2] == 6.0
