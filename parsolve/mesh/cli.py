"""``parsolve mesh convert IN OUT.h5``: a Gmsh file (its physical groups; MSH 4.1 and 2.2
streamed by chunks, ``gmshmesh.convert``) or any mesh file meshio reads → the parallel mesh file
(``mesh.h5mesh``), with exactly the regions reading IN gives.
Exit 2 with one line naming the file and the key on bad input; the input is never overwritten."""

from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path

from parsolve.errors import InputError


class _Parser(argparse.ArgumentParser):
    def error(self, message: str) -> None:   # usage errors: one line, exit 2
        raise InputError(message, "parsolve mesh")


def _parser() -> argparse.ArgumentParser:
    p = _Parser(prog="parsolve mesh", description="Mesh files.")
    sub = p.add_subparsers(dest="command", required=True, parser_class=_Parser)
    c = sub.add_parser("convert", help="a mesh file (any meshio format, Gmsh physical groups) "
                       "→ the parallel mesh file OUT.h5 that every rank reads a slice of")
    c.add_argument("input")
    c.add_argument("output")
    c.add_argument("--force", action="store_true", help="replace OUT.h5 if it exists")
    return p


def convert(source: str, target: str, force: bool = False) -> str:
    """Read ``source``, write ``target``; returns a one-line summary."""
    from parsolve.mesh import gmsh, gmshmesh
    from parsolve.mesh.h5mesh import is_mesh_h5, read_whole, write_mesh
    from parsolve.mesh.reader import read_mesh

    if not is_mesh_h5(target):
        raise InputError("the output must be an .h5 file", target, "OUT")
    src, out = Path(source), Path(target)
    if out.resolve() == src.resolve() or out.exists() and src.exists() and out.samefile(src):
        raise InputError("the output is the input: it is never overwritten", target, "OUT")
    if out.exists() and not force:
        raise InputError("the output exists (give --force to replace it)", target, "OUT")
    tmp = out.with_name(out.name + ".part")
    try:
        if gmsh.ours(source):   # streamed: never the whole file in memory
            cell_type, cells, points, groups = gmshmesh.convert(source, str(tmp))
        else:
            mesh = read_whole(source) if is_mesh_h5(source) else read_mesh(source)
            write_mesh(mesh, str(tmp))
            cell_type, cells, points = mesh.cell_type, mesh.num_cells, mesh.num_points
            groups = len(mesh.cell_groups) + len(mesh.facet_groups) + len(mesh.node_groups)
        os.replace(tmp, out)   # nothing half-written under the output's name
    except OSError as exc:
        raise InputError(f"cannot write ({exc.strerror or exc})", target, "OUT") from None
    finally:
        tmp.unlink(missing_ok=True)
    return f"{target}: {cells} {cell_type} cells, {points} points, {groups} groups"


def main(argv: list[str]) -> int:
    """The subcommand: rank 0 converts (the output is written once), every rank returns its
    status."""
    from mpi4py import MPI

    comm = MPI.COMM_WORLD
    status = 0
    if comm.rank == 0:
        try:
            args = _parser().parse_args(argv)
            print(convert(args.input, args.output, args.force), flush=True)
        except InputError as exc:
            print(f"parsolve: {exc.oneline()}", file=sys.stderr, flush=True)
            status = 2
    return comm.bcast(status, root=0)
