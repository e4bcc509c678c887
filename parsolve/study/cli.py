"""``parsolve study STUDY.toml [--out DIR] [--executor local|slurm] [--parallel N]
[--target ERR] [--reduced] [--save PREFIX]``.

Writes DIR/study.md, DIR/study.csv and DIR/study.png (and PREFIX.md/.csv/.png with --save),
prints the table's answer. Exit 2 on bad input (one line naming the file and the key), 3 when
a run failed (the table still lists it), 4 when its files cannot be written (a full disk: one
line, no report file cut)."""

from __future__ import annotations

import argparse
import shutil
import sys
import tomllib
from pathlib import Path

from parsolve.errors import EXIT_INPUT, EXIT_OUTPUT, EXIT_SOLVER, InputError


def _parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="parsolve study", description="Accuracy against cost.")
    p.add_argument("study", help="study file (TOML)")
    p.add_argument("--out", help="folder of the runs and the report (default: STUDY_runs)")
    p.add_argument("--executor", choices=("local", "slurm"), help="default: the study's, else local")
    p.add_argument("--parallel", help="runs at a time (local executor)")
    p.add_argument("--target", help="requested error of the first quantity")
    p.add_argument("--reduced", action="store_true", help="apply the study's [reduced] table (CI)")
    p.add_argument("--save", metavar="PREFIX", help="also write PREFIX.md, PREFIX.csv, PREFIX.png")
    return p


def run(args) -> int:
    from parsolve.scene import parse_scene
    from parsolve.study import report
    from parsolve.study.config import load_study
    from parsolve.study.execute import check_quantities, run_grid
    from parsolve.study.grid import expand
    from parsolve.io.whole import write_whole

    parallel, target = _numbers(args)
    study = load_study(args.study, reduced=args.reduced)
    root = Path(args.out or Path(args.study).stem + "_runs")
    _check_outputs(root, args.save)
    settings = expand(study)
    check_quantities(study, settings)
    dim = parse_scene(tomllib.loads(settings[0].scene_text), str(study.scene)).dim
    rows = run_grid(study, settings, root, args.executor or study.executor,
                    parallel or study.parallel)
    target = target if target is not None else study.target
    a = report.analyse(study, rows, dim, target)
    head, body = report.table(study, rows, a)
    text = report.markdown(study, rows, a, head, body, target)
    root.mkdir(parents=True, exist_ok=True)
    write_whole(root / "study.md", lambda name: Path(name).write_text(text))
    write_whole(root / "study.csv", lambda name: report.write_csv(Path(name), head, body))
    write_whole(root / "study.png",
                lambda name: report.picture(Path(name), study, rows, a, target))
    if args.save:
        Path(args.save).parent.mkdir(parents=True, exist_ok=True)
        for ext in ("md", "csv", "png"):
            write_whole(f"{args.save}.{ext}",
                        lambda name, ext=ext: shutil.copyfile(root / f"study.{ext}", name))
    print(text)
    failed = [r.setting.name for r in rows if not r.ok]
    if failed:
        print(f"parsolve study: {len(failed)} run(s) failed: {', '.join(failed)}", file=sys.stderr)
        return EXIT_SOLVER
    return 0


def _numbers(args) -> tuple[int | None, float | None]:
    """--parallel (a positive integer) and --target (a positive finite number), read here so
    that a bad value is one line naming the option."""
    from parsolve.study.config import positive_number

    parallel = target = None
    if args.parallel is not None:
        try:
            parallel = int(args.parallel)
        except ValueError:
            parallel = 0
        if parallel < 1:
            raise InputError(f"expected a positive integer, got {args.parallel!r}", "command line",
                             "--parallel")
    if args.target is not None:
        try:
            target = float(args.target)
        except ValueError:
            target = None
        if not positive_number(target):
            raise InputError(f"expected a positive finite number, got {args.target!r}",
                             "command line", "--target")
    return parallel, target


def _check_outputs(root: Path, save: str | None) -> None:
    """The run folder and the report files can be written (checked before the first run)."""
    from parsolve.batch.api import folder_problem

    problem = folder_problem(root)
    if problem:
        raise InputError(problem, "command line", "--out")
    for name in ("study.md", "study.csv", "study.png"):
        if (root / name).is_dir():
            raise InputError(f"{root / name} is a folder, not a file", "command line", "--out")
    if save:
        problem = folder_problem(Path(save).parent)
        if problem:
            raise InputError(problem, "command line", "--save")
        for ext in ("md", "csv", "png"):
            if Path(f"{save}.{ext}").is_dir():
                raise InputError(f"{save}.{ext} is a folder, not a file", "command line", "--save")


def main(argv: list[str]) -> int:
    args = _parser().parse_args(argv)
    try:
        return run(args)
    except InputError as exc:
        print(f"parsolve study: {exc.oneline()}", file=sys.stderr)
        return EXIT_INPUT
    except OSError as exc:   # its runs' folder or its report (a full disk): one line
        print(f"parsolve study: {exc.filename or args.out}: cannot write ({exc.strerror or exc}); "
              "the runs already complete are kept: run the study again once there is room",
              file=sys.stderr)
        return EXIT_OUTPUT
