"""The effects parsolve knows: each names its scene section, how to read it, and how to build
itself on the mesh. Adding an effect is one line here (and its module). The order is the
fields' order in the system (the displacement first)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

from parsolve.effects import (contact, contact_penalty, diffusion, elasticity, exchange,
                              solubility, springs, thermal_expansion)


@dataclass(frozen=True)
class Entry:
    section: str                 # scene section: "[[diffusion]]" (array) or "[solubility]"
    array: bool                  # an array of tables (one effect per entry) or one table
    parse: Callable              # (Table, dim) -> spec
    build: Callable              # (spec, context) -> Effect
    coupling: bool = False       # built once the fields of the others are known
    whole: bool = False          # one effect for all the section's entries (build gets the list)
    primary: bool = False        # its field is the one loads and relations name by default
    hypothesis: bool = False     # the scene must give [model] hypothesis
    # what the scene checks before reading the mesh: the fields a spec declares {name:
    # components}, and the regions and evolutions it names [(name, dotted key)]
    fields: Callable = lambda spec, dim: {}
    regions: Callable = lambda spec: []
    evolutions: Callable = lambda spec: []
    labels: Callable = lambda specs: []   # what the scene's list of effects adds for them


def _build_diffusion(spec, ctx):
    time = ctx.scene.time
    return diffusion.Diffusion(spec, ctx.mesh, ctx.regions, ctx.scene.thickness, ctx.scene.source,
                               lumped=time is None or time.mass == "lumped")


def _build_solubility(spec, ctx):
    return solubility.Solubility(spec, ctx.mesh, ctx.regions, ctx.fields, ctx.scene.evolutions,
                                 ctx.scene.source)


def _parse_contact(t, dim):
    """[[contact]]: ``formulation`` and the baselines' keys are consumed first (so that
    contact.parse, which checks that no key is left, stays as it is)."""
    baseline = contact_penalty.read_formulation(t)
    return contact_penalty.with_baseline(contact.parse(t, dim), baseline)


def _build_contact(spec, ctx):
    # formulation = "relations" (the paper's) or a baseline (penalty, augmented Lagrangian)
    if isinstance(spec, contact_penalty.BaselineSpec):
        return contact_penalty.build(spec, ctx.mesh, ctx.regions, ctx.fields, ctx.scene)
    return contact.Contact(spec, ctx.mesh, ctx.regions, ctx.fields, ctx.scene.source,
                           radial=ctx.scene.hypothesis == "axisymmetric")


EFFECTS: dict[str, Entry] = {
    # [[materials]]: small-strain elasticity, linear or not, one effect for every entry
    "elasticity": Entry("materials", True, elasticity.parse, elasticity.build, whole=True,
                        primary=True, hypothesis=True,
                        fields=elasticity.declared_fields, regions=elasticity.regions,
                        labels=elasticity.labels),
    "diffusion": Entry("diffusion", True, lambda t, dim: diffusion.parse(t, dim), _build_diffusion,
                       fields=lambda spec, dim: {spec.field: 1},
                       regions=lambda spec: [(m.region, m.key + ".region") for m in spec.materials]),
    "solubility": Entry("solubility", False, lambda t, dim: solubility.parse(t), _build_solubility,
                        coupling=True,
                        regions=lambda spec: [(name, key.rsplit(".", 1)[0] + ".region")
                                              for name, _, key in spec.saturation],
                        evolutions=lambda spec: [(spec.evolution, spec.key + ".evolution")]),
    # the temperature of a diffusion field as an eigenstrain of the elasticity
    "thermal_expansion": Entry("thermal_expansion", True, thermal_expansion.parse,
                               thermal_expansion.build, coupling=True,
                               regions=thermal_expansion.regions),
    # on parts (surfaces gathered once), the relations form and the penalty and augmented-
    # Lagrangian baselines alike
    "contact": Entry("contact", True, _parse_contact, _build_contact, coupling=True),
    # h (T − T∞(t)) through a boundary region of a scalar field: a facet term and its load
    "exchange": Entry("exchange", True, exchange.parse, exchange.build, coupling=True,
                      regions=exchange.regions),
    "springs": Entry("springs", True, springs.parse,
                     lambda spec, ctx: springs.Springs(spec, ctx.mesh, ctx.regions, ctx.scene),
                     regions=springs.regions),
}
