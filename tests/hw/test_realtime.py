"""ElapsedSteps: simulator steps that keep pace with the wall clock."""

import pytest

from inflarm_hw.realtime import ElapsedSteps


class FakeClock:
    def __init__(self) -> None:
        self.now = 100.0

    def __call__(self) -> float:
        return self.now


def test_steps_are_the_time_that_passed_capped_and_never_negative():
    clock = FakeClock()
    steps = ElapsedSteps(max_step_s=1.0, clock=clock)
    clock.now += 0.02
    assert steps() == pytest.approx(0.02)
    clock.now += 0.035  # a late callback: the whole 35 ms, not the nominal period
    assert steps() == pytest.approx(0.035)
    clock.now += 60.0  # a suspended process: the rest is skipped
    assert steps() == 1.0
    assert steps() == 0.0
    clock.now -= 1.0  # a clock that went back gives no step
    assert steps() == 0.0


def test_a_bad_cap_is_rejected():
    with pytest.raises(ValueError, match='max_step_s > 0'):
        ElapsedSteps(max_step_s=0.0)
