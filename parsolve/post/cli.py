"""``parsolve post RESULT.h5 [RESULT2.h5 ...] [--summary] [--x SPEC --y SPEC [--csv F] [--png F]]
[--derive OUT.h5]``. Exit 2 with one line naming the file and the spec on bad input."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from parsolve.errors import InputError


def _parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="parsolve post", description="Curves, derived fields and "
                                "summaries of result files. SPEC: see parsolve/post/spec.py.")
    p.add_argument("results", nargs="+", help="result files (HDF5)")
    p.add_argument("--summary", action="store_true", help="steps, status, extremes, relations")
    p.add_argument("--x", metavar="SPEC", help="abscissa, e.g. time or relation:control:primal")
    p.add_argument("--y", metavar="SPEC", help="ordinate, e.g. relation:control:multiplier")
    p.add_argument("--csv", metavar="FILE", help="write the curves (default: print them)")
    p.add_argument("--png", metavar="FILE", help="plot the curves, one line per file")
    p.add_argument("--derive", metavar="OUT.h5", help="copy of RESULT.h5 with strain, von Mises, "
                   "principal stresses, nodal stress per material region (+ XDMF)")
    p.add_argument("--recover", action="store_true", help="make a killed run's result (status "
                   "running) readable: its finished steps, status \"interrupted: killed "
                   "(recovered)\" (parsolve/io/recover.py)")
    return p


def _curves(args) -> list:
    from parsolve.post.result import Result
    from parsolve.post.spec import parse, evaluate

    xs, ys = parse(args.x, "--x"), parse(args.y, "--y")
    curves = []
    for path in args.results:
        with Result(path) as res:
            curves.append((res.stem, evaluate(res, xs), evaluate(res, ys)))
    return curves


def _derivable(src: str) -> None:
    """--derive copies a finished result: one a run is still writing (between two steps a
    parallel-output file opens) is refused."""
    from parsolve.io.recover import being_written, lock_path

    if being_written(src):
        raise InputError(f"a run is writing it now (lock held on {lock_path(src)}): --derive "
                         "reads a finished result; derive once the run has ended", src, "--derive")


def run(args) -> None:
    from parsolve.post.result import Result

    if not (args.summary or args.x or args.y or args.derive):
        raise InputError("nothing to do: give --summary, --x/--y or --derive", args.results[0])
    if bool(args.x) != bool(args.y):
        raise InputError("--x and --y go together", args.results[0], "--x" if args.x else "--y")
    from parsolve.post.curves import check_output

    from parsolve.batch.api import folder_problem

    for key in ("csv", "png", "derive"):
        check_output(getattr(args, key), f"--{key}", args.results)
        if getattr(args, key):   # a folder that refuses files whatever its permissions say
            problem = folder_problem(Path(getattr(args, key)).parent)
            if problem:
                raise InputError(problem, getattr(args, key), f"--{key}")
    for path in args.results:   # every input readable before anything is printed or written
        with Result(path) as res:
            if args.summary:    # a summary vouches for the whole file: every value read
                res.verify()
    if args.derive:
        _derivable(args.results[0])
    if args.summary:
        from parsolve.post.summary import summary

        texts = []
        for path in args.results:   # all read (a damaged dataset found) before any is printed
            with Result(path) as res:
                texts.append(summary(res))
        print("\n".join(texts))
    if args.x:
        from parsolve.post.curves import write_csv, write_png

        curves = _curves(args)
        if args.csv:
            write_csv(args.csv, args.x, args.y, curves)
        if args.png:
            write_png(args.png, args.x, args.y, curves)
        if not (args.csv or args.png):
            for label, x, y in curves:
                for a, b in zip(x, y):
                    print(f"{label}\t{a:.10g}\t{b:.10g}")
    if args.derive:
        from parsolve.post.derive import derive

        if len(args.results) != 1:
            raise InputError("--derive takes one result file", args.results[1], "--derive")
        src = args.results[0]
        if Path(args.derive).resolve() == Path(src).resolve():
            raise InputError("--derive writes a copy: the input is never overwritten", src, "--derive")
        names = derive(src, args.derive)
        print(f"{args.derive}: " + ", ".join(f"/{g}/{n}" for g, ns in names.items() for n in ns)
              + f"; {Path(args.derive).with_suffix('.xdmf')}")


def main(argv: list[str]) -> int:
    from parsolve.io import recover

    args = _parser().parse_args(argv)
    try:
        if args.recover:
            for path in args.results:
                print(recover.recover(path)[1])
            if not (args.summary or args.x or args.y or args.derive):
                return 0
        run(args)
    except InputError as exc:
        more = "" if "lock held" in exc.message else recover.hint(exc.source)
        print(f"parsolve post: {exc.oneline()}{more}", file=sys.stderr)
        return 2
    except BrokenPipeError:  # | head
        return 0
    except (OSError, RuntimeError) as exc:  # a file changed or damaged under us: one line
        where = getattr(exc, "filename", None) or ", ".join(args.results)
        print(f"parsolve post: {where}: {' '.join(str(exc).split())}", file=sys.stderr)
        return 2
    return 0
