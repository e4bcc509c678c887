"""The step-cut rule (parsolve/driver.py ``StepSchedule.cut``, parsolve/diagnostics.py
``loads_held``): a failed step is halved up to 6 times in a row, and no more once the same cause
that no smaller step removes held at two sizes in a row."""

from types import SimpleNamespace

import pytest

from parsolve.driver import StepSchedule
from parsolve.evolution import CONSTANT, RAMP, Evolution

FRICTION = ("every closed node of 'base' slides",)


def schedule(times=(0.5, 1.0)) -> StepSchedule:
    return StepSchedule(SimpleNamespace(steps=SimpleNamespace(automatic=False), times=times))


def test_a_step_is_halved_six_times_without_a_cause():
    s = schedule()
    tried = [s.next()]
    while s.cut(tried[-1]):
        tried.append(s.next())
    assert tried == [0.5 ** k for k in range(1, 8)] and s.cuts == 6 and s.hopeless == ()


def test_the_same_cause_at_two_sizes_stops_the_cuts():
    s = schedule()
    assert s.cut(s.next(), FRICTION)           # seen once: cut (it may pass at half)
    assert not s.cut(s.next(), FRICTION)       # seen again at half the size: stop
    assert s.cuts == 1 and s.hopeless == FRICTION


@pytest.mark.parametrize("causes", [[FRICTION, (), FRICTION, ()], [(), FRICTION, (), FRICTION]])
def test_a_cause_between_attempts_without_it_does_not_stop(causes):
    s = schedule()
    for cause in causes:
        assert s.cut(s.next(), cause)
    assert s.cuts == 4 and s.hopeless == ()


def test_a_converged_step_forgets_the_cause():
    """A cause seen before a step converged (a cut step saved on the way) is not the next
    attempt's previous one."""
    s = schedule()
    assert s.cut(s.next(), FRICTION)
    s.done(s.next(), 0.0)          # t = 0.25 converged: the scene's 0.5 is still ahead
    assert s.next() == 0.5
    assert s.cut(s.next(), FRICTION) and s.hopeless == ()


def test_evolutions_constant_over_an_interval():
    assert CONSTANT.constant_over(0.0, 0.5) and CONSTANT.constant_over(0.5, 3.0)
    assert not RAMP.constant_over(0.0, 0.5) and RAMP.constant_over(1.0, 2.0)
    hold = Evolution("hold", (0.0, 1.0, 2.0, 3.0), (0.0, 1.0, 1.0, 0.0))
    assert hold.constant_over(1.0, 2.0) and hold.constant_over(1.25, 1.5)
    assert not hold.constant_over(0.5, 2.0) and not hold.constant_over(1.0, 2.5)
    # the same value at both ends, another between them
    assert not hold.constant_over(0.5, 2.5)
