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
import os
import sys
from pathlib import Path

USAGE = """parsolve run SCENE [-o OUT.h5] [--export-system DIR] [--output-mode swmr|parallel|auto]
                    [-q | -v] [PETSc options]
       parsolve check SCENE [-q | -v] [PETSc options]
       parsolve {study,batch,post,mesh} ...   (parsolve COMMAND --help)
       parsolve --version"""
COMMANDS = {  # what ``parsolve --help`` lists, in order
    "run": "run a scene: progress on rank 0, results in an HDF5 file (+ XDMF)",
    "check": "validate a scene (mesh, regions, relations, PETSc options) without solving",
    "study": "accuracy against cost over a grid of runs (parsolve study --help)",
    "batch": "many runs, locally or as a SLURM job array (parsolve batch --help)",
    "post": "curves, line profiles, nodal fields and summaries of results (parsolve post --help)",
    "mesh": "mesh files: conversion, inspection (parsolve mesh --help)",
}
LONG_FLAGS = ("--output", "--export-system", "--output-mode", "--quiet", "--verbose", "--version",
              "--help")
VALUED = ("-o", "--output", "--export-system", "--output-mode")  # flags of ours that take the next word
SHORT_FLAGS = ("-o", "-h", "-q", "-v")   # every other single-dash word is PETSc's


class UsageError(Exception):
    """A bad command line: exit status 2, one line."""


class _Parser(argparse.ArgumentParser):
    def error(self, message: str):  # one line, no usage block
        raise UsageError(message)


class _Version(argparse.Action):
    """``--version``: parsolve's, PETSc's and the MPI library's (imported only when asked)."""

    def __init__(self, option_strings, dest, **kwargs):
        super().__init__(option_strings, dest, nargs=0, help="print the versions and exit")

    def __call__(self, parser, namespace, values, option_string=None):
        print(versions())
        parser.exit(0)


def versions() -> str:
    """One line: parsolve, PETSc (petsc4py), MPI (the library mpi4py runs on)."""
    import petsc4py

    from parsolve import __version__
    from parsolve.version import petsc_version

    petsc4py.init([sys.argv[0]])
    from mpi4py import MPI

    mpi = MPI.Get_library_version().strip().splitlines()[0]
    return (f"parsolve {__version__}; PETSc {petsc_version()} (petsc4py {petsc4py.__version__}); "
            f"MPI {'.'.join(map(str, MPI.Get_version()))}: {mpi}")


def _verbosity(p: argparse.ArgumentParser) -> None:
    g = p.add_mutually_exclusive_group()
    g.add_argument("-q", "--quiet", dest="level", action="store_const", const=0,
                   help="errors and the final line only")
    g.add_argument("-v", "--verbose", dest="level", action="store_const", const=2,
                   help="also each Newton iteration's residual and each linear solve's Krylov "
                        "iterations")
    p.set_defaults(level=1)


def _parser() -> argparse.ArgumentParser:
    listing = "\n".join(f"  {name:<8s}{text}" for name, text in COMMANDS.items())
    p = _Parser(prog="parsolve", usage=USAGE, allow_abbrev=False,
                formatter_class=argparse.RawDescriptionHelpFormatter,
                description="Parallel finite elements with (non-)associated relations.\n\n"
                            f"commands:\n{listing}",
                epilog="Single-dash words other than -o, -h, -q, -v are PETSc options (with their\n"
                       "value): -ksp_monitor, -log_view, -pc_type lu, ...; they win over the\n"
                       "scene's [solver.options]. Exit status: 0 done, 2 invalid input, 3 the solver\n"
                       "failed, 4 the results could not be written, 130/143 interrupted.")
    p.add_argument("--version", action=_Version)
    sub = p.add_subparsers(dest="command", required=True, parser_class=_Parser, metavar="COMMAND",
                             help=argparse.SUPPRESS)   # (listed in the description)
    run = sub.add_parser("run", help=COMMANDS["run"], allow_abbrev=False, prog="parsolve run",
                         usage="parsolve run SCENE [-o OUT.h5] [--export-system DIR] "
                               "[--output-mode swmr|parallel|auto] [-q | -v] [PETSc options]")
    run.add_argument("scene", help="scene file (TOML)")
    run.add_argument("-o", "--output", help="result file (HDF5); default: the scene's [output] "
                                            "file, else SCENE.h5 in the current directory")
    run.add_argument("--export-system", metavar="DIR",
                     help="write the first assembled system (PETSc binary) to DIR")
    run.add_argument("--output-mode", choices=("swmr", "parallel", "auto"), default=None,
                     help="swmr (default): rank 0 writes, readers can follow the run; parallel: "
                          "every rank writes its rows (MPI-IO), no live reading; auto: parallel "
                          "on 2+ ranks from 1M DOFs")
    _verbosity(run)
    check = sub.add_parser("check", help=COMMANDS["check"], allow_abbrev=False,
                           prog="parsolve check",
                           usage="parsolve check SCENE [-q | -v] [PETSc options]")
    check.add_argument("scene", help="scene file (TOML)")
    _verbosity(check)
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
    exactly ``-o``, ``-h``, ``-q`` and ``-v`` (so ``-options_left``, ``-on_error_abort``,
    ``-options_file F`` reach PETSc intact), each with its value when the next word is not an
    option. A double-dash word must be one of ours: ``--outptu`` is an error with a
    suggestion."""
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
        if word in SHORT_FLAGS or word.startswith("--") or not _is_option(word):
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


def output_path(args, scene) -> tuple[str, str, str]:
    """(path, source, key) of the result file: -o, else [output] file, else SCENE.h5."""
    if args.output:
        return args.output, "command line", "-o"
    if scene.output:
        return scene.output, scene.source, "output.file"
    return Path(args.scene).stem + ".h5", scene.source, "output.file"


def check_output(path: str, source: str, key: str, inputs: list[Path],
                 export_dir: str | None = None) -> None:
    """The result file (and the XDMF beside it) must be a writable file that is no input."""
    from parsolve.errors import InputError

    def fail(message: str, src: str = source, k: str = key) -> InputError:
        return InputError(message, src, k)

    out = Path(path)
    targets = [out, out.with_suffix(".xdmf"), out.with_suffix(".xdmf.h5")]
    for target in targets:
        for inp in inputs:
            if _same(target, inp):
                raise fail(f"{target} would overwrite the input file {inp}")
    if out.is_dir():
        raise fail(f"{out} is a folder, not a result file")
    parent = out.parent if str(out.parent) else Path(".")
    if parent.exists() and not parent.is_dir():
        raise fail(f"cannot write {out}: {parent} is a file, not a folder")
    if not parent.exists():
        raise fail(f"cannot write {out}: folder {parent} does not exist")
    if not os.access(parent, os.W_OK | os.X_OK):
        raise fail(f"cannot write {out}: folder {parent} is read-only")
    for target in targets:
        if target.exists() and (target.is_dir() or not os.access(target, os.W_OK)):
            raise fail(f"cannot write {target}: it is a folder or read-only")
    if export_dir is not None:
        d = Path(export_dir)
        if d.exists() and not d.is_dir():
            raise fail(f"--export-system {d} is a file, not a folder", "command line",
                       "--export-system")


def lock_output(comm, out: str, source: str, key: str):
    """Rank 0 locks the result (parsolve.io.lock) and every rank learns the verdict: a result
    another run is writing is an InputError, raised before any output is touched. Returns the
    lock on rank 0 (None elsewhere)."""
    from parsolve.errors import InputError
    from parsolve.io.lock import OutputLock

    lock, verdict = None, None
    if comm.rank == 0:
        lock = OutputLock(out)
        try:
            verdict = "ok" if lock.acquire() else "busy"
        except OSError as exc:
            verdict = f"cannot lock {lock.path}: {exc.strerror or exc}"
        if verdict == "ok" and not lock.reserve():
            lock.release()          # no room even for the reserve: no result is started
            verdict = "full"
    verdict = comm.bcast(verdict, root=0)
    if verdict == "full":
        from parsolve.errors import OutputError
        from parsolve.io.lock import RESERVE_BYTES

        raise OutputError(f"{out}: No space left on device (disk full): the "
                          f"{RESERVE_BYTES >> 20} MiB kept beside the result to close it do not "
                          f"fit in {Path(out).parent}; nothing written")
    if verdict == "busy":
        raise InputError(f"{out} is being written by another run (lock held on "
                         f"{out}.lock)", source, key)
    if verdict != "ok":
        raise InputError(verdict, source, key)
    return lock


def _same(a: Path, b: Path) -> bool:
    try:
        return a.resolve() == b.resolve() or (a.exists() and b.exists() and a.samefile(b))
    except OSError:
        return False


def _check_all_regions(model) -> None:
    """Regions no effect uses are evaluated too: their selectors must be valid and finite."""
    scene = model.scene
    resolver = model.regions()
    for name, spec in scene.regions.items():
        resolver(name, spec.key)


def _validate_options(comm, model, cli_options: dict[str, str]) -> None:
    from parsolve.solvers import options as opt
    from parsolve.solvers.linear import preset_options

    scene = model.scene
    multiplied = [r for r in model.relations if not r.eliminable()]
    preset = preset_options(scene.solver.preset, all(r.associated for r in multiplied),
                            bool(multiplied))
    opt.validate(comm, scene.solver.prefix, preset, scene.solver.options, cli_options,
                 scene.source)


def main(argv: list[str] | None = None) -> int:
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
    from parsolve import progress

    progress.configure(args.level, comm.rank)
    if args.level > progress.QUIET:   # the factorization's parts, from PETSc's event log
        from parsolve.solvers import factor_log

        factor_log.start()
    log = say if args.level > progress.QUIET else (lambda *words: None)
    try:
        cli_options = parse_cli(petsc_args)
    except ValueError as exc:
        say(f"parsolve: {exc}", sys.stderr)
        return 2
    lock = None
    try:
        from parsolve.mesh import memory
        from parsolve.model import build_model
        from parsolve.scene import load_scene

        scene = load_scene(args.scene)
        if args.command == "run":
            out, source, key = output_path(args, scene)
            inputs = [Path(args.scene)] + ([scene.mesh.file] if scene.mesh.file else [])
            check_output(out, source, key, inputs, args.export_system)
            lock = lock_output(comm, out, source, key)
        with memory.agreed_over(comm):
            model = build_model(scene, comm)
        _check_all_regions(model)
        _validate_options(comm, model, cli_options)
        for warning in model.mesh.warnings:
            log(f"parsolve: warning: {warning}", sys.stderr)
        if args.command == "check":
            mesh = model.mesh
            say(f"{args.scene}: ok ({getattr(mesh, 'num_global_points', mesh.num_points)} nodes, "
                f"{getattr(mesh, 'num_global_cells', mesh.num_cells)} "
                f"{model.mesh.cell_type} cells, {len(model.relations)} relations, "
                f"{len(scene.times)} steps; effects: {', '.join(scene.effects)})")
            return 0
        from parsolve.driver import run

        from parsolve.interrupts import interruptible

        with interruptible(comm):
            run(comm, model, out, cli_options, args.export_system, log=log,
                output=args.output_mode)
        for name in unused_options(scene.solver.prefix, {**scene.solver.options, **cli_options}):
            log(f"parsolve: warning: PETSc option {name} was not used by any solver object",
                sys.stderr)
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
    finally:
        progress.configure(progress.QUIET)   # (main called in a process that goes on)
        if lock is not None:
            lock.release()


if __name__ == "__main__":
    sys.exit(main())
