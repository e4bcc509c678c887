"""The relation kinds parsolve knows: each names its ``type``, reads its own keys and builds
its rows (its module). A ``[[relations]]`` entry names one; adding a kind is a module and one
entry here.

Every entry reads the same common keys (``name``, ``type``, ``field``, ``value`` where it has
one, ``evolution``, ``dual``, ``sense``, ``eliminate``, ``maximum``, ``report``) and its own
(``parse``: region, components, terms, ...)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

from parsolve.relation_kinds import dirichlet, periodic, strain, ties
from parsolve.relation_kinds.base import own_regions


@dataclass(frozen=True)
class RelationEntry:
    parse: Callable             # (Table, RelationSpec, Declared) -> None: its own keys
    build: Callable             # (RelationSpec, Where, Evolution) -> Relation
    value: tuple | None         # the types its value takes (None: it has no value)
    regions: Callable = own_regions   # spec -> [(region, dotted key)], checked before the mesh
    holds: bool = False         # its rows hold single DOFs at given values (a reaction each)
    ties: bool = False          # its rows tie pairs of DOFs (u_a − u_b = 0)
    per_rank: bool = False      # each row constrains one DOF or node: built per rank, each
    #                             row by that node's owner (``build``), eliminated or not
    description: str = ""


RELATIONS: dict[str, RelationEntry] = {
    "dirichlet": RelationEntry(dirichlet.parse, dirichlet.build, (float, str), holds=True,
                               per_rank=True,
                               description="a value per node and component (a number or an "
                                           "expression of x, y, z)"),
    "equal": RelationEntry(ties.parse_equal, ties.build_equal, None, per_rank=True,
                           description="equal values of a component over a region"),
    "mean": RelationEntry(ties.parse_mean, ties.build_combination, (float,),
                          description="the mean of a component over a region [minus "
                                      "another's]"),
    "linear": RelationEntry(ties.parse_linear, ties.build_combination, (float,),
                            description="Σ coefficient × (sum or mean of a component over a "
                                        "region)"),
    "strain": RelationEntry(strain.parse, strain.build, (float,),
                            description="the strain n·ε·n of a region (its mean) or of each "
                                        "of its cells"),
    "periodic": RelationEntry(periodic.parse, periodic.build, None, ties=True, per_rank=True,
                              description="each node of a region tied to its partner of a "
                                          "target at x + translation"),
}
