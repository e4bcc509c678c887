"""The effects parsolve knows: each names its scene section, how to read it, and how to build
itself on the mesh. Adding an effect is one line here (and its module)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

from parsolve.effects import contact, diffusion, solubility


@dataclass(frozen=True)
class Entry:
    section: str                 # scene section: "[[diffusion]]" (array) or "[solubility]"
    array: bool                  # an array of tables (one effect per entry) or one table
    parse: Callable              # (Table, dim) -> spec
    build: Callable              # (spec, context) -> Effect
    coupling: bool = False       # built once the fields of the others are known


def _build_diffusion(spec, ctx):
    return diffusion.Diffusion(spec, ctx.mesh, ctx.regions, ctx.scene.thickness, ctx.scene.source)


def _build_solubility(spec, ctx):
    return solubility.Solubility(spec, ctx.mesh, ctx.regions, ctx.fields, ctx.scene.evolutions,
                                 ctx.scene.source)


def _build_contact(spec, ctx):
    return contact.Contact(spec, ctx.mesh, ctx.regions, ctx.fields, ctx.scene.source)


# elasticity is read from [[materials]] by the scene itself (the historical layout)
EFFECTS: dict[str, Entry] = {
    "diffusion": Entry("diffusion", True, lambda t, dim: diffusion.parse(t, dim), _build_diffusion),
    "solubility": Entry("solubility", False, lambda t, dim: solubility.parse(t), _build_solubility,
                        coupling=True),
    "contact": Entry("contact", True, contact.parse, _build_contact, coupling=True),
}
