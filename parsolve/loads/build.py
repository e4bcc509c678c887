"""The scene's ``[[loads]]`` as vector terms: each load declares one, on its region's facets,
cells or nodes, with its pattern and evolution, as an effect declares its own; its forces are
its registry entry's at the step's instant."""

from __future__ import annotations

from typing import Iterable

import numpy as np

from parsolve.fem.element_matrices import NodeForces, Term
from parsolve.loads.base import Instant, Where
from parsolve.loads.registry import LOADS


class SceneLoads:
    """The declarer of the scene's loads (``terms``, ``vector_values``: what an effect's
    vector terms answer to) on this rank's part of the mesh."""

    name = "loads"

    def __init__(self, mesh, scene, regions, fields):
        thickness = scene.thickness if mesh.dim == 2 else 1.0
        self.loads: dict[Term, tuple] = {}   # term -> (spec, where)
        for spec in scene.loads:
            region = regions(spec.region, spec.key + ".region")
            where = Where(mesh, region, fields, thickness, regions, scene)
            domain = LOADS[spec.kind].domain
            term = Term(spec.field, None, pattern=spec.pattern, timed=spec.timed,
                        evolution=scene.evolutions[spec.evolution],
                        **{"facets": {"facets": region.facets},
                           "cells": {"cells": region.cells},
                           "nodes": {"nodes": region.nodes}}[domain])
            self.loads[term] = (spec, where)

    def terms(self) -> list[Term]:
        return list(self.loads)

    def vector_values(self, term: Term, cells: np.ndarray, at: Instant) -> Iterable[NodeForces]:
        spec, where = self.loads[term]
        return LOADS[spec.kind].forces(spec, where, at)
