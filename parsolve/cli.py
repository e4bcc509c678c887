"""Command line: ``parsolve run SCENE [-o OUT.h5] [--export-system DIR] [PETSc options]`` and
``parsolve check SCENE``.

Exit status: 0 success, 2 invalid input (one line naming the file and key), 3 the solver
failed (finished steps kept in the result file). Any other exception on any rank aborts the
whole MPI job instead of leaving the other ranks hanging.
"""

from __future__ import annotations

import argparse
import signal
import sys
from contextlib import contextmanager
from pathlib import Path

USAGE = "parsolve {run,check,study,batch,post} SCENE [-o OUT.h5] [--export-system DIR] [PETSc options]"


def _parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="parsolve", usage=USAGE,
                                description="Parallel finite elements with (non-)associated relations.")
    sub = p.add_subparsers(dest="command", required=True)
    run = sub.add_parser("run", help="run a scene")
    run.add_argument("scene")
    run.add_argument("-o", "--output", help="result file (HDF5); default: the scene's [output] "
                                            "file, else SCENE.h5 in the current directory")
    run.add_argument("--export-system", metavar="DIR",
                     help="write the first assembled system (PETSc binary) to DIR")
    check = sub.add_parser("check", help="validate a scene (mesh, regions, relations) without solving")
    check.add_argument("scene")
    return p


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


@contextmanager
def _signals_interrupt():
    """SIGINT / SIGTERM raise Interrupted at once (the result file is closed with the status
    "interrupted: ..." and its finished steps); the previous handlers come back afterwards."""
    from parsolve.errors import Interrupted

    def handler(signum, frame):
        raise Interrupted(signum, signal.Signals(signum).name)

    previous = {s: signal.signal(s, handler) for s in (signal.SIGINT, signal.SIGTERM)}
    try:
        yield
    finally:
        for s, h in previous.items():
            signal.signal(s, h)


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    if argv and argv[0] in SUBCOMMANDS:
        import importlib

        return importlib.import_module(f"parsolve.{argv[0]}.cli").main(argv[1:])
    args, petsc_args = _parser().parse_known_args(argv)
    import petsc4py

    petsc4py.init([sys.argv[0]] + petsc_args)
    from mpi4py import MPI

    from parsolve.errors import InputError, Interrupted, OutputError, SolverError
    from parsolve.solvers.options import parse_cli

    comm = MPI.COMM_WORLD
    _abort_on_error(comm)

    def say(message: str, stream=sys.stdout) -> None:
        if comm.rank == 0:
            print(message, file=stream, flush=True)

    try:
        cli_options = parse_cli(petsc_args) if args.command == "run" else {}
    except ValueError as exc:
        say(f"parsolve: {exc}", sys.stderr)
        return 2
    try:
        from parsolve.model import build_model
        from parsolve.scene import load_scene

        scene = load_scene(args.scene)
        model = build_model(scene)
        if args.command == "check":
            say(f"{args.scene}: ok ({model.mesh.num_points} nodes, {model.mesh.num_cells} "
                f"{model.mesh.cell_type} cells, {len(model.relations)} relations, "
                f"{len(scene.times)} steps; effects: {', '.join(scene.effects)})")
            return 0
        from parsolve.driver import run

        out = args.output or scene.output or (Path(args.scene).stem + ".h5")
        with _signals_interrupt():
            run(comm, model, out, cli_options, args.export_system, log=say)
        say(f"results: {out}")
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
