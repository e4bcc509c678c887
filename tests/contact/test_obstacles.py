"""Rigid obstacles: plane, cylinder (2D circle, 3D axis), sphere; bad input."""

from __future__ import annotations

import numpy as np
import pytest

from parsolve.contact import obstacles
from parsolve.errors import InputError


def frame_ok(p):
    dim = p.dim
    assert np.allclose(np.linalg.norm(p.normal, axis=1), 1.0, atol=1e-15)
    gram = np.einsum("nix,njx->nij", p.tangents, p.tangents)
    assert np.allclose(gram, np.eye(dim - 1), atol=1e-15)
    assert np.allclose(np.einsum("nix,nx->ni", p.tangents, p.normal), 0.0, atol=1e-15)
    if dim == 3:
        assert np.allclose(np.cross(p.tangents[:, 0], p.tangents[:, 1]), p.normal, atol=1e-15)
    else:
        assert np.allclose(p.tangents[:, 0], np.column_stack([-p.normal[:, 1], p.normal[:, 0]]))
    assert p.master.shape == (len(p), 0) and np.all(p.facet == -1) and p.paired.all()


def test_inclined_plane_2d_and_3d():
    pts = np.array([[1.0, 2.0], [-0.5, 0.1], [3.0, -1.0]])
    p = obstacles.plane(pts, [0, 1, 2], origin=[0.0, 0.5], normal=[1.0, 1.0])
    n = np.array([1.0, 1.0]) / np.sqrt(2)
    assert np.allclose(p.gap, (pts - [0.0, 0.5]) @ n, atol=1e-15)
    assert np.allclose(p.point @ n, 0.5 / np.sqrt(2), atol=1e-15)
    frame_ok(p)
    pts3 = np.random.default_rng(2).normal(size=(10, 3))
    p3 = obstacles.plane(pts3, np.arange(10), origin=[0, 0, 1], normal=[0, 0, 3])
    assert np.allclose(p3.gap, pts3[:, 2] - 1.0, atol=1e-15)
    assert np.allclose(p3.normal, [0, 0, 1])
    frame_ok(p3)


def test_circle_cylinder_sphere():
    rng = np.random.default_rng(5)
    x2 = rng.uniform(-2, 2, size=(20, 2))
    c = obstacles.cylinder(x2, np.arange(20), centre=[0.1, -0.2], radius=0.7)
    r = np.linalg.norm(x2 - [0.1, -0.2], axis=1)
    assert np.allclose(c.gap, r - 0.7, atol=1e-15)
    assert np.allclose(np.linalg.norm(c.point - [0.1, -0.2], axis=1), 0.7, atol=1e-14)
    frame_ok(c)
    bore = obstacles.cylinder(x2, np.arange(20), centre=[0.1, -0.2], radius=0.7, inside=True)
    assert np.allclose(bore.gap, 0.7 - r) and np.allclose(bore.normal, -c.normal)
    x3 = rng.uniform(-2, 2, size=(20, 3))
    cyl = obstacles.cylinder(x3, np.arange(20), centre=[0, 0, 0], radius=0.5, axis=[0, 0, 2])
    assert np.allclose(cyl.gap, np.linalg.norm(x3[:, :2], axis=1) - 0.5, atol=1e-15)
    assert np.allclose(cyl.tangents[:, 0], [0, 0, 1])
    frame_ok(cyl)
    sph = obstacles.sphere(x3, np.arange(20), centre=[0, 0, 1], radius=0.3)
    assert np.allclose(sph.gap, np.linalg.norm(x3 - [0, 0, 1], axis=1) - 0.3, atol=1e-15)
    frame_ok(sph)


@pytest.mark.parametrize("call", [
    lambda: obstacles.plane(np.zeros((2, 2)), [0], [0, 0], [0, 0], "s.toml", "contact.plane"),
    lambda: obstacles.plane(np.zeros((2, 3)), [0], [0, 0, 0], [1, 0], "s.toml", "k"),
    lambda: obstacles.cylinder(np.ones((2, 2)), [0], [0, 0], -1.0),
    lambda: obstacles.cylinder(np.ones((2, 3)), [0], [0, 0, 0], 1.0),
    lambda: obstacles.sphere(np.ones((2, 3)), [0], [0, np.nan, 0], 1.0),
])
def test_bad_obstacles(call):
    with pytest.raises(InputError):
        call()


def test_error_names_file_and_key():
    with pytest.raises(InputError) as e:
        obstacles.plane(np.zeros((2, 2)), [0], [0, 0], [0, 0], "scene.toml", "contact.obstacle")
    assert "scene.toml: contact.obstacle:" in str(e.value) and "non-zero" in str(e.value)
