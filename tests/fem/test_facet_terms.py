"""A facet term (``Term.facets``): a boundary integral whose element arrays come in facet
blocks (``fem.integrals.facet_matrices``) and whose slots are those of the cells holding its
facets. The assembled operator against a brute-force dense assembly of k ∫ u · v ds over a
boundary region, its products, and the blocks' size changing nothing beyond round-off; at 1, 2, 3 ranks."""

from __future__ import annotations

import tomllib

import numpy as np
import pytest
from mpi4py import MPI

from conftest import stiffness_block
from helpers.saddle import SCENE
from helpers.terms import check_products

from parsolve.effects.base import Effect
from parsolve.fem.element_matrices import ElementMatrices, Term
from parsolve.fem.integrals import facet_matrices, facet_rule, mass, weighted_mass
from parsolve.model import build_model
from parsolve.scene import parse_scene
from parsolve.solvers.system import SaddleSystem

COMM = MPI.COMM_WORLD
K = 7.5   # the support's stiffness per unit area


def k_of(x: np.ndarray) -> np.ndarray:
    """A stiffness varying along the face (read at the quadrature points)."""
    return K * (1.0 + x[..., 0] + 2.0 * x[..., 1])


class FaceSupport(Effect):
    """∫ k(x) u · v ds over the facets of a boundary region (an elastic support)."""

    name = "support"

    def __init__(self, model, region: str, block: int | None = None):
        self.mesh, self.block = model.mesh, block
        self.thickness = model.scene.thickness
        self.term = Term("u", "u", facets=model.regions()(region, "t").facets)

    def terms(self) -> list[Term]:
        return [self.term]

    def term_values(self, term: Term, cells: np.ndarray) -> ElementMatrices:
        def values(rule, _):
            m = weighted_mass(rule, k_of(rule.points))[0]
            out = np.zeros((4,) + m.shape)
            out[0] = out[3] = m            # (x, x) and (y, y)
            return out
        return facet_matrices(self.mesh.points, term.facets, self.mesh.facet_type,
                              self.thickness, values, rows=4, block=self.block)


def brute(model, region: str) -> np.ndarray:
    """Dense ∫ k u · v ds (input numbering), facet by facet with np.add.at."""
    mesh = model.mesh
    facets = model.regions()(region, "t").facets
    rule = facet_rule(mesh.points[facets], mesh.facet_type, model.scene.thickness)
    w = rule.weights * k_of(rule.points)
    m = np.einsum("qa,qb,nq->nab", rule.N, rule.N, w)
    out = np.zeros((mesh.num_points * 2,) * 2)
    for c in range(2):
        rows = np.broadcast_to(facets[:, :, None] * 2 + c, m.shape)
        cols = np.broadcast_to(facets[:, None, :] * 2 + c, m.shape)
        np.add.at(out, (rows.ravel(), cols.ravel()), m.ravel())
    return out


@pytest.mark.parametrize("cell,region", [("quad", "right"), ("triangle", "top"),
                                         ("triangle6", "bottom")])
def test_a_facet_term_on_a_boundary_region(cell, region):
    text = SCENE.format(cell=cell, preset="direct", eliminate="false")

    def model():
        return build_model(parse_scene(tomllib.loads(text), "t.toml", text), COMM)

    bare = stiffness_block(COMM, SaddleSystem(COMM, model()))
    got = {}
    for block in (None, 2):   # blocks of 2 facets: the same operator (sums in another order)
        m = model()
        m.effects.append(FaceSupport(m, region, block))
        got[block] = stiffness_block(COMM, SaddleSystem(COMM, m)) - bare
    scale = np.abs(bare).max()   # (the differences: round-off of K's entries)
    np.testing.assert_allclose(got[None], got[2], rtol=0, atol=1e-15 * scale)
    whole = build_model(parse_scene(tomllib.loads(text), "t.toml", text))
    expected = brute(whole, region)
    assert np.count_nonzero(expected.any(axis=1)) < len(expected) / 2
    # the support's total: k integrated over the face, twice (two components)
    rule = facet_rule(whole.mesh.points[whole.regions()(region, "t").facets],
                      whole.mesh.facet_type, whole.scene.thickness)
    np.testing.assert_allclose(expected.sum(), 2 * (rule.weights * k_of(rule.points)).sum(),
                               rtol=1e-13)
    np.testing.assert_allclose(got[None], expected, rtol=0, atol=1e-12 * scale)

    # its products (the default evaluate, the composition's product) are K_support q
    check_products(whole, FaceSupport(whole, region, 3), expected, K)


def test_weighted_mass_is_the_facets_mass():
    """``weighted_mass`` cell-last is ``mass`` scaled: the exchange's h ∫ N Nᵀ ds."""
    coords = np.array([[[0.0, 0.0], [2.0, 0.0], [1.0, 0.1]],
                       [[2.0, 0.0], [2.0, 1.0], [2.1, 0.5]]])
    rule = facet_rule(coords, "line3")
    np.testing.assert_allclose(weighted_mass(rule, 3.0)[0].transpose(2, 0, 1),
                               3.0 * mass(rule), rtol=1e-15)
