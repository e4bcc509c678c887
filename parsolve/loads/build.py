"""The scene's loads → named patterns on this rank's part of the mesh (collective: counts and
measures are the whole mesh's)."""

from __future__ import annotations

from parsolve.loads.base import Instant, LoadPattern, TimedPart, Where
from parsolve.loads.registry import LOADS


def load_patterns(mesh, scene, regions, fields) -> dict[str, LoadPattern]:
    """{pattern name: LoadPattern} of ``scene.loads``: a load whose values name t is a part
    assembled again at each instant; the others are assembled once (expressions of the
    coordinates alone at t = 0)."""
    thickness = scene.thickness if mesh.dim == 2 else 1.0
    patterns: dict[str, LoadPattern] = {}
    for spec in scene.loads:
        region = regions(spec.region, spec.key + ".region")
        where = Where(mesh, region, fields, thickness, regions, scene)
        assemble = LOADS[spec.kind].assemble
        first = assemble(spec, where, Instant(scene.times[0] if scene.times else 0.0))  # errors now
        part = TimedPart(lambda at, s=spec, w=where, a=assemble: a(s, w, at)) if spec.timed \
            else first
        patterns.setdefault(spec.pattern, LoadPattern(spec.pattern)).parts.append(
            (part, scene.evolutions[spec.evolution]))
    return patterns
