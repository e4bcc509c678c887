"""Command line: ``parsolve run SCENE [-o OUT.h5] [--export-system DIR] [PETSc options]`` and
``parsolve check SCENE [PETSc options]``.

Exit status: 0 success, 2 invalid input (one line naming the file and key), 3 the solver
failed (finished steps kept in the result file). Any other exception on any rank aborts the
whole MPI job instead of leaving the other ranks hanging.

Checks, in order, identically on every rank and before any output file is opened: the
arguments, the scene, the output paths, the mesh (size, shape), the model, the PETSc options.
"""

from __future__ import annotations

import argparse
import difflib
import sys

USAGE = ("parsolve {run,check,study,batch,post} SCENE [-o OUT.h5] [--export-system DIR] "
         "[--output-mode swmr|parallel|auto] [PETSc options]")
LONG_FLAGS = ("--output", "--export-system", "--output-mode", "--restart", "--help")
VALUED = ("-o", "--output", "--export-system", "--output-mode", "--restart")  # flags of ours that take the next word


class UsageError(Exception):
    """A bad command line: exit status 2, one line."""


class _Parser(argparse.ArgumentParser):
    def error(self, message: str):  # one line, no usage block
        raise UsageError(message)


def _parser() -> argparse.ArgumentParser:
    p = _Parser(prog="parsolve", usage=USAGE, allow_abbrev=False,
                description="Parallel finite elements with (non-)associated relations.")
    sub = p.add_subparsers(dest="command", required=True, parser_class=_Parser)
    run = sub.add_parser("run", help="run a scene", allow_abbrev=False)
    run.add_argument("scene")
    run.add_argument("-o", "--output", help="result file (HDF5); default: the scene's [output] "
                                            "file, else SCENE.h5 in the current directory")
    run.add_argument("--export-system", metavar="DIR",
                     help="write the first assembled system (PETSc binary) to DIR")
    run.add_argument("--output-mode", choices=("swmr", "parallel", "auto"), default=None,
                     help="swmr (default): rank 0 writes, readers can follow the run; parallel: "
                          "every rank writes its rows (MPI-IO), no live reading; auto: parallel "
                          "on 2+ ranks from 1M DOFs")
    run.add_argument("--restart", metavar="RESULT.h5",
                     help="continue the result of an earlier run of this scene from its last "
                          "finished step (a new result: its steps, then the new ones)")
    check = sub.add_parser("check", help="validate a scene (mesh, regions, relations, PETSc "
                                         "options) without solving", allow_abbrev=False)
    check.add_argument("scene")
    return p


def _is_option(word: str) -> bool:
    """A dash word that is not a negative number. (Here, not in solvers.options: importing
    petsc4py.PETSc before petsc4py.init(args) would make PETSc ignore the command line.)"""
    if not word.startswith("-"):
        return False
    try:
        float(word)
        return False
    except ValueError:
        return True


def split_args(argv: list[str]) -> tuple[list[str], list[str]]:
    """(parsolve's words, PETSc's words). PETSc options are single-dash words other than
    exactly ``-o`` and ``-h`` (so ``-options_left``, ``-on_error_abort``, ``-options_file F``
    reach PETSc intact), each with its value when the next word is not an option. A
    double-dash word must be one of ours: ``--outptu`` is an error with a suggestion."""
    ours, petsc = [], []
    i = 0
    while i < len(argv):
        word = argv[i]
        i += 1
        if word.startswith("--") and word != "--":
            flag = word.split("=", 1)[0]
            if flag not in LONG_FLAGS:
                close = difflib.get_close_matches(flag, LONG_FLAGS, n=1)
                hint = f" (did you mean {close[0]}?)" if close else \
                    f" (known: {', '.join(LONG_FLAGS)}; PETSc options take one dash)"
                raise UsageError(f"unknown option {flag}{hint}")
        if word in ("-o", "-h") or word.startswith("--") or not _is_option(word):
            ours.append(word)
            if word in VALUED and i < len(argv):
                ours.append(argv[i])
                i += 1
            continue
        petsc.append(word)
        if i < len(argv) and not _is_option(argv[i]):
            petsc.append(argv[i])
            i += 1
    return ours, petsc


def _abort_on_error(comm) -> None:
    """An uncaught exception on one rank aborts every rank (mpi4py's advice)."""
    previous = sys.excepthook

    def hook(kind, value, tb):
        previous(kind, value, tb)
        sys.stderr.flush()
        comm.Abort(1)

    if comm.size > 1:
        sys.excepthook = hook


# Commands that live in their own subpackage: ``parsolve.<name>.cli.main(argv) -> int``.
SUBCOMMANDS = ("study", "batch", "post")


def main(argv: list[str] | None = None) -> int:
    """The exit status of one command. ``run`` and ``check`` are :mod:`parsolve.api`'s
    ``run`` and ``check`` (its checks, in its order); here only the arguments, the messages
    and the exit statuses."""
    argv = sys.argv[1:] if argv is None else argv
    if argv and argv[0] in SUBCOMMANDS:
        import importlib

        return importlib.import_module(f"parsolve.{argv[0]}.cli").main(argv[1:])
    usage_error, petsc_args = None, []
    try:
        ours, petsc_args = split_args(argv)
        args = _parser().parse_args(ours)
    except UsageError as exc:
        usage_error = exc
    import petsc4py

    petsc4py.init([sys.argv[0]] + petsc_args)
    from mpi4py import MPI

    from parsolve.errors import InputError, Interrupted, OutputError, SolverError
    from parsolve.solvers.options import parse_cli, unused_options

    comm = MPI.COMM_WORLD
    _abort_on_error(comm)

    def say(message: str, stream=sys.stdout) -> None:
        if comm.rank == 0:
            print(message, file=stream, flush=True)

    if usage_error is not None:
        say(f"parsolve: {usage_error}", sys.stderr)
        return 2
    try:
        cli_options = parse_cli(petsc_args)
    except ValueError as exc:
        say(f"parsolve: {exc}", sys.stderr)
        return 2
    from parsolve import api

    try:
        if args.command == "check":
            scene = api.Scene.from_file(args.scene)
            model = api.check(scene, comm, cli_options)
            for warning in model.mesh.warnings:
                say(f"parsolve: warning: {warning}", sys.stderr)
            mesh = model.mesh
            say(f"{args.scene}: ok ({getattr(mesh, 'num_global_points', mesh.num_points)} nodes, "
                f"{getattr(mesh, 'num_global_cells', mesh.num_cells)} "
                f"{model.mesh.cell_type} cells, {len(model.relations)} relations, "
                f"{len(scene.spec.times)} steps; effects: {', '.join(scene.spec.effects)})")
            return 0
        scene = api.Scene.from_file(args.scene)
        result = api.run(scene, args.output, comm, cli_options, restart=args.restart,
                         output_mode=args.output_mode, export_system=args.export_system,
                         log=say, warn=lambda message: say(message, sys.stderr))
        solver = scene.spec.solver
        for name in unused_options(solver.prefix, {**solver.options, **cli_options}):
            say(f"parsolve: warning: PETSc option {name} was not used by any solver object",
                sys.stderr)
        say(f"results: {result.path}")
        return 0
    except Interrupted as exc:
        say(f"parsolve: interrupted by {exc.name}; the finished steps are in the result file",
            sys.stderr)
        return exc.exit_status
    except OutputError as exc:
        say(f"parsolve: cannot write the results: {exc}", sys.stderr)
        return 4
    except InputError as exc:
        say(f"parsolve: {exc.oneline()}", sys.stderr)
        return 2
    except SolverError as exc:
        say(f"parsolve: solver failed: {exc}", sys.stderr)
        return 3


if __name__ == "__main__":
    sys.exit(main())
