"""Runs ``parsolve check`` and ``parsolve run`` on every case directory named in a JSON file,
in one process per rank (started by mpirun), and writes each case's exit status and error
lines (rank 0's) to the JSON file given second. Before each case, PROGRESS (third argument)
names it: a case that hangs is the last one there. After each case every rank must be at the
same case (a collective call left pending would show here)."""

import contextlib
import io
import json
import sys
from pathlib import Path

from mpi4py import MPI

from parsolve.cli import main


def run_case(directory: Path, command: str) -> tuple[int, list[str]]:
    args = [command, str(directory / "scene.toml")]
    if command == "run":
        args += ["-o", str(directory / "out.h5")]
    err = io.StringIO()
    with contextlib.redirect_stderr(err):
        try:
            code = main(args)
        except SystemExit as exc:
            code = exc.code
    return code, [line for line in err.getvalue().splitlines() if line.strip()]


def main_runner(cases_file: str, results_file: str, progress_file: str) -> None:
    comm = MPI.COMM_WORLD
    cases = json.loads(Path(cases_file).read_text())
    results = {}
    for name, directory, commands in cases:
        for command in commands:
            if comm.rank == 0:
                Path(progress_file).write_text(f"{name} {command}\n")
            code, lines = run_case(Path(directory), command)
            together = comm.allgather((name, command))
            results[f"{name} {command}"] = {"code": code, "lines": lines,
                                            "together": len(set(together)) == 1}
    if comm.rank == 0:
        Path(results_file).write_text(json.dumps(results))


if __name__ == "__main__":
    main_runner(*sys.argv[1:4])
