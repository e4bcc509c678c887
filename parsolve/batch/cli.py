"""``parsolve batch JOBS.toml [--executor local|slurm] [--parallel N] [--dry-run] [--collect]
[--no-wait] [--rerun] [-o ROOT]``.

Exit status: 0 every run complete (or submitted with --no-wait, or a dry run); 2 invalid job
file or scene (one line naming the file and the key; nothing runs); 3 some run did not
complete (see the manifest); 4 the batch's own files could not be written (a full disk:
one line); 1 the executor could not start (no sbatch); 130 interrupted.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from parsolve.errors import EXIT_INPUT, EXIT_OUTPUT, EXIT_SOLVER, InputError

USAGE = ("parsolve batch JOBS.toml [--executor local|slurm] [--parallel N] [--dry-run] "
         "[--collect] [--no-wait] [--rerun] [-o ROOT]")


def _parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="parsolve batch", usage=USAGE,
                                description="Many runs of a scene, locally or as a SLURM job array.")
    p.add_argument("jobs", help="job file (TOML)")
    p.add_argument("--executor", choices=("local", "slurm"), help="default: the job file's, else local")
    p.add_argument("--parallel", type=int, help="local executor: runs at a time")
    p.add_argument("-o", "--output", help="batch root (default: the job file's 'output')")
    p.add_argument("--dry-run", action="store_true", help="validate and list the runs; run nothing")
    p.add_argument("--collect", action="store_true", help="rewrite the manifest from the run folders")
    p.add_argument("--no-wait", action="store_true", help="slurm: submit and return")
    p.add_argument("--rerun", action="store_true", help="run every run, complete or not")
    return p


def main(argv: list[str]) -> int:
    args = _parser().parse_args(argv)
    from parsolve.batch import api, manifest
    from parsolve.batch.collect import summary
    from parsolve.batch.jobs import load_jobs

    try:
        if args.parallel is not None and args.parallel < 1:
            raise InputError("must be at least 1", "command line", "--parallel")
        jobs = load_jobs(args.jobs, validate=not args.collect)
        root = Path(args.output).resolve() if args.output else jobs.root
        problem = None if args.collect else api.folder_problem(root)
        if problem:  # before anything is written (mkdir would fail half way)
            raise InputError(problem, *(("command line", "-o") if args.output else (args.jobs, "output")))
    except InputError as exc:
        print(f"parsolve: {exc.oneline()}", file=sys.stderr)
        return EXIT_INPUT
    if args.collect:
        if not (root / manifest.RUNS).exists():
            print(f"parsolve batch: {root} holds no batch (no {manifest.RUNS})", file=sys.stderr)
            return 1
        try:
            rows = manifest.write(root, manifest.load_runs(root))
        except OSError as exc:
            return _cannot_write(exc, root)
        print(f"{root / manifest.MANIFEST}: {len(rows)} runs: {summary(rows)}")
        return 0 if all(r["status"] == "complete" for r in rows) else EXIT_SOLVER
    if args.dry_run:
        _list(jobs.runs, root)
        return 0
    executor = args.executor or jobs.executor
    try:
        outcomes = api.execute(jobs.runs, root, executor, args.parallel or jobs.parallel,
                               jobs.slurm, resume=not args.rerun, wait=not args.no_wait,
                               log=lambda m: print(m, flush=True))
    except KeyboardInterrupt:
        print("parsolve batch: interrupted", file=sys.stderr)
        return 130
    except (RuntimeError, ValueError) as exc:
        print(f"parsolve batch: {exc}", file=sys.stderr)
        return 1
    except OSError as exc:
        return _cannot_write(exc, root)
    counts = {}
    for o in outcomes:
        counts[o.status.split(":")[0]] = counts.get(o.status.split(":")[0], 0) + 1
    print(f"{root / manifest.MANIFEST}: {len(outcomes)} runs: "
          + ", ".join(f"{n} {s}" for s, n in sorted(counts.items())))
    ok = ("complete", "submitted", "running elsewhere")
    return 0 if all(o.status in ok for o in outcomes) else EXIT_SOLVER


def _cannot_write(exc: OSError, root: Path) -> int:
    """The batch's own files (a full disk): one line naming the file, not a traceback."""
    print(f"parsolve batch: {exc.filename or root}: cannot write ({exc.strerror or exc}); the "
          "runs' results already written stay, run the batch again once there is room",
          file=sys.stderr)
    return EXIT_OUTPUT


def _list(runs, root: Path) -> None:
    from parsolve.batch.api import is_done

    print(f"{len(runs)} runs under {root}:")
    for r in runs:
        state = "complete" if is_done(root / r.name, r) else "to run"
        print(f"  {r.name}  ranks={r.ranks}  {r.params}  {' '.join(r.args)}  [{state}]")
