"""``parsolve post RESULT.h5 [RESULT2.h5 ...] [--summary] [--x SPEC --y SPEC [--y SPEC ...]]
[--line P0 P1 N --y SPEC ... [--step K|last|all]] [--csv F] [--png F] [--derive OUT.h5]
[--recover]``. Exit 2 with one line naming the file and the spec on bad input."""

from __future__ import annotations

import argparse
import re
import sys
from pathlib import Path

from parsolve.errors import InputError

GRAMMAR = """\
SPEC (one value per saved step; --x and every --y):
  time                                   load parameter of the step
  step                                   step number (1, 2, ...; 0: the unloaded state)
  relation:NAME:multiplier[:SEL]         λ of a relation; SEL = row number, sum or mean
  relation:NAME:primal[:SEL]             A q of a relation (one-row relations need no SEL)
  relation:NAME:resultant:COMP           Σ of its reactions: x, y, z (forces), mx, my, mz
                                         (moments about the origin; 2D: mz), or a scalar
                                         field's name
  field:NAME:COMP@X,Y[,Z]                nodal field at a point (the element's shape functions)
  cell_field:NAME:COMP@X,Y[,Z]           value of the cell containing the point
  max:field:NAME:COMP[@REGION]           largest nodal value (signed), over a region or all
  maxabs:field:NAME:COMP[@REGION]        largest |value|
  norm:field:NAME                        L2 norm sqrt(∫ |f|² dΩ)
  energy                                 strain energy ½ ∫ ε : C ε dΩ (linear elastic scenes)
COMP: x, y, z for vectors; xx, yy, zz, yz, xz, xy for Voigt tensors (2D: xx, yy, xy); or a
number (0, 1, ...). With --line, --y is field:NAME[:COMP] or cell_field:NAME[:COMP].

Curves start at the unloaded state (t = 0, every value 0) when the scene starts from rest: a
static scene whose loads and relation values are all 0 at t = 0 and that has no contact.

examples:
  parsolve post bar.h5 --summary
  parsolve post bar.h5 --x relation:control:primal --y relation:control:multiplier --png fd.png
  parsolve post a.h5 b.h5 --x time --y field:displacement:x@1,0.05 \\
      --y relation:left_x:multiplier:sum --csv curves.csv
  parsolve post kirsch.h5 --derive kirsch_derived.h5   (then: --y max:field:von_mises)
  parsolve post kirsch.h5 --line 0,1 0,10 50 --y field:stress:xx --step all --csv lig.csv
"""


def _parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="parsolve post", formatter_class=argparse.RawDescriptionHelpFormatter,
        usage="parsolve post RESULT.h5 [RESULT2.h5 ...] [--summary] [--x SPEC --y SPEC "
              "[--y SPEC ...]] [--line P0 P1 N --y SPEC ... [--step K|last|all]] [--csv FILE] "
              "[--png FILE] [--derive OUT.h5] [--recover]",
        description="Curves, line profiles, derived and nodal fields, and summaries of result "
                    "files.", epilog=GRAMMAR)
    # points with a negative first coordinate (--line -1,0 1,0 20) are values, not options
    p._negative_number_matcher = re.compile(r"^-(\d+\.?\d*|\.\d+)([eE][-+]?\d+)?(,[-+.\deE]+)*$")
    p.add_argument("results", nargs="+", help="result files (HDF5)")
    p.add_argument("--summary", action="store_true", help="steps, status, extremes (where: "
                   "coordinates, node or cell), relations, contacts per step")
    p.add_argument("--x", metavar="SPEC", help="abscissa, e.g. time or relation:control:primal")
    p.add_argument("--y", metavar="SPEC", action="append", help="ordinate, e.g. "
                   "relation:control:multiplier; repeat for several curves")
    p.add_argument("--line", nargs=3, metavar=("P0", "P1", "N"), help="sample --y along the "
                   "segment P0 P1 (X,Y[,Z] each) at N evenly spaced points")
    p.add_argument("--step", metavar="K", help="--line: the step (1, 2, ...), last (default) "
                   "or all")
    p.add_argument("--csv", metavar="FILE", help="write the curves or the profile (default: "
                                                 "print them)")
    p.add_argument("--png", metavar="FILE", help="plot them (matplotlib)")
    p.add_argument("--derive", metavar="OUT.h5", help="copy of RESULT.h5 with strain, von Mises, "
                   "principal stresses, nodal stress per material region, and every cell field "
                   "projected onto the nodes (lumped L²) as /fields/NAME (+ XDMF)")
    p.add_argument("--recover", action="store_true", help="make a killed run's result (status "
                   "running) readable: its finished steps, status \"interrupted: killed "
                   "(recovered)\"")
    return p


def _curves(args) -> list:
    """(file label, x, [y per --y], step numbers) per file, from the unloaded state when the
    scene starts from rest."""
    from parsolve.post.curves import with_rest
    from parsolve.post.result import Result
    from parsolve.post.spec import evaluate, parse

    xs, ys = parse(args.x, "--x"), [parse(y, "--y") for y in args.y]
    curves = []
    for path in args.results:
        with Result(path) as res:
            curves.append(with_rest(res, evaluate(res, xs), [evaluate(res, y) for y in ys]))
    return curves


def _derivable(src: str) -> None:
    """--derive copies a finished result: one a run is still writing (between two steps a
    parallel-output file opens) is refused."""
    from parsolve.io.recover import being_written, lock_path

    if being_written(src):
        raise InputError(f"a run is writing it now (lock held on {lock_path(src)}): --derive "
                         "reads a finished result; derive once the run has ended", src, "--derive")


def _profiles(args) -> None:
    from parsolve.post import line
    from parsolve.post.curves import write_whole
    from parsolve.post.result import Result

    p0, p1, n = line.parse_line(args.line, args.results[0])
    rows, profiles = [], []
    for path in args.results:
        with Result(path) as res:
            steps = line.steps_of(res, args.step)
            s, xs, values = line.sample(res, p0, p1, n, args.y, steps)
            rows += line.table(res, s, xs, values, args.y, steps)
            profiles += [(f"{res.stem} {spec} step {k + 1}", s, v[i])
                         for spec, v in zip(args.y, values) for i, k in enumerate(steps)]
    if args.csv:
        write_whole(args.csv, "--csv", lambda name: line.write_csv(name, rows))
    if args.png:
        write_whole(args.png, "--png",
                    lambda name: line.write_png(name, profiles, ", ".join(args.y)))
    if not (args.csv or args.png):
        print("\t".join(rows[0]))
        for row in rows:
            print("\t".join(str(v) for v in row.values()))


def _check(args) -> None:
    first = args.results[0]
    if not (args.summary or args.x or args.y or args.derive or args.line):
        raise InputError("nothing to do: give --summary, --x/--y, --line/--y or --derive", first)
    if args.line and args.x:
        raise InputError("--line draws against the distance along the line: no --x", first, "--x")
    if args.y and not (args.x or args.line):
        raise InputError("--y needs --x (curves) or --line (profiles)", first, "--y")
    if (args.x or args.line) and not args.y:
        raise InputError("--x and --line need at least one --y", first,
                         "--x" if args.x else "--line")
    if args.step is not None and not args.line:
        raise InputError("--step goes with --line", first, "--step")


def run(args) -> None:
    from parsolve.post.result import Result

    _check(args)
    from parsolve.post.curves import check_output

    from parsolve.batch.api import folder_problem

    for key in ("csv", "png", "derive"):
        check_output(getattr(args, key), f"--{key}", args.results)
        if getattr(args, key):   # a folder that refuses files whatever its permissions say
            problem = folder_problem(Path(getattr(args, key)).parent)
            if problem:
                raise InputError(problem, getattr(args, key), f"--{key}")
    if args.derive:   # (first: a swmr file being written does not open at all)
        _derivable(args.results[0])
    for path in args.results:   # every input readable before anything is printed or written
        with Result(path) as res:
            if args.summary:    # a summary vouches for the whole file: every value read
                res.verify()
    if args.summary:
        from parsolve.post.summary import summary

        texts = []
        for path in args.results:   # all read (a damaged dataset found) before any is printed
            with Result(path) as res:
                texts.append(summary(res))
        print("\n".join(texts))
    if args.x:
        from parsolve.post.curves import write_csv, write_png, write_whole

        curves = _curves(args)
        if args.csv:
            write_whole(args.csv, "--csv", lambda name: write_csv(name, args.x, args.y, curves))
        if args.png:
            write_whole(args.png, "--png", lambda name: write_png(name, args.x, args.y, curves))
        if not (args.csv or args.png):
            print("\t".join(["file", "step", args.x] + args.y))
            for label, x, ys, steps in curves:
                for k in range(len(x)):
                    print("\t".join([label, str(steps[k]), f"{x[k]:.10g}"]
                                    + [f"{y[k]:.10g}" for y in ys]))
    if args.line:
        _profiles(args)
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
            if not (args.summary or args.x or args.y or args.derive or args.line):
                return 0
        run(args)
    except InputError as exc:
        more = "" if "lock held" in exc.message or exc.key == "--recover" else \
            recover.hint(exc.source)
        print(f"parsolve post: {exc.oneline()}{more}", file=sys.stderr)
        return 2
    except BrokenPipeError:  # | head
        return 0
    except (OSError, RuntimeError) as exc:  # a file changed or damaged under us: one line
        where = getattr(exc, "filename", None) or ", ".join(args.results)
        print(f"parsolve post: {where}: {' '.join(str(exc).split())}", file=sys.stderr)
        return 2
    return 0
