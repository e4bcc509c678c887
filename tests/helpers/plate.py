"""The 2 × 1 plate of quads pulled on its right side (plane stress, E = 1e9, ν = 0.25) on which
the tests of relations split across the ranks build their scenes (``helpers.scene.scene``:
each states its mesh size, regions and relations), and the relation tables they use."""

from __future__ import annotations

PLATE = {
    "mesh": {"generator": "rectangle", "lx": 2.0, "ly": 1.0, "nx": 24, "ny": 12, "cell": "quad"},
    "model": {"hypothesis": "plane_stress"},
    "materials": [{"E": 1e9, "nu": 0.25}],
    "loads": [{"name": "pull", "region": "right", "total_force": [1.0, 0.0]}],
}


def dirichlet(name: str, region: str, component: str, **more) -> dict:
    """A Dirichlet relation on one component of a region's nodes."""
    return {"name": name, "type": "dirichlet", "region": region, "components": [component],
            **more}


def mean(name: str, region: str, value: float, component: str = "x", **more) -> dict:
    """A mean relation on one component over a region."""
    return {"name": name, "type": "mean", "region": region, "component": component,
            "value": value, **more}
