"""parsolve.progress: phase lines with their time on rank 0, levels, "still running" lines."""

import re
import time

import pytest

from parsolve import progress


def reporter(level, rank=0, alive=progress.ALIVE):
    lines = []
    return progress.Reporter(level, rank, lines.append, alive), lines


def test_phase_lines_levels_and_nesting():
    rep, lines = reporter(progress.NORMAL)
    with rep.phase("pattern"):
        time.sleep(0.02)
        with rep.phase("inner"):
            pass
    with rep.phase("factorization", progress.VERBOSE):
        pass
    rep.say("detail", progress.VERBOSE)
    assert len(lines) == 2
    inner, outer = (re.fullmatch(r"( +)(\S+)\s+(\d+\.\d{3}) s", line) for line in lines)
    assert inner.group(2) == "inner" and len(inner.group(1)) == 4
    assert outer.group(2) == "pattern" and len(outer.group(1)) == 2
    assert 0.02 <= float(outer.group(3)) < 5


def test_quiet_and_other_ranks_say_nothing():
    for rep, lines in (reporter(progress.QUIET), reporter(progress.VERBOSE, rank=1)):
        with rep.phase("partition"):
            pass
        rep.say("x", progress.NORMAL)
        assert lines == []


def test_a_long_phase_says_it_is_alive():
    rep, lines = reporter(progress.NORMAL, alive=0.05)
    with rep.phase("analysis"):
        time.sleep(0.3)    # alive lines after 0.05, 0.1, 0.2 s (doubling), none after the end
    alive, last = lines[:-1], lines[-1]
    assert 1 <= len(alive) <= 3 and all(re.fullmatch(r"  analysis: still running \(0 s\)", a)
                                        for a in alive), lines
    assert re.fullmatch(r"  analysis\s+0\.\d{3} s", last), last
    time.sleep(0.25)       # the watcher has ended with the phase
    assert len(lines) == len(alive) + 1


def test_an_announced_phase_and_the_first_factorization():
    rep, lines = reporter(progress.NORMAL)
    with rep.phase("analysis", announce=True):
        pass
    assert lines[0] == "  analysis ..." and lines[1].startswith("  analysis ") and len(lines) == 2
    progress.configure(progress.NORMAL, 0, lines.append)
    try:
        with progress.factorization(first=True):
            pass
        with progress.factorization(first=False):   # later ones: -v only
            pass
    finally:
        progress.configure(progress.QUIET)
    assert lines[2] == "  analysis+factorization ..." and len(lines) == 4
    assert lines[3].startswith("  analysis+factorization ") and lines[3].endswith(" s")


def test_the_process_reporter_and_an_error_inside_a_phase():
    lines = []
    progress.configure(progress.VERBOSE, 0, lines.append)
    try:
        assert progress.timed("numbering", lambda a, b: a + b, 2, b=3) == 5
        progress.detail("newton 1: residual 1e-3")
        with pytest.raises(ValueError), progress.phase("operator"):
            raise ValueError("inside")
    finally:
        progress.configure(progress.QUIET)
    assert [line.split()[0] for line in lines] == ["numbering", "newton", "operator"]
    assert lines[1] == "    newton 1: residual 1e-3"
    progress.detail("not shown")
    assert len(lines) == 3
