"""ProblemReporter: warnings throttled per kind of problem, guards that keep callbacks alive."""

import pytest

from inflarm_msgs_json.ros.problems import InputError, ProblemReporter, problem_kind


class Logger:
    def __init__(self) -> None:
        self.lines: list[tuple[str, str]] = []

    def warning(self, text: str) -> None:
        self.lines.append(('warning', text))

    def error(self, text: str) -> None:
        self.lines.append(('error', text))


class Clock:
    def __init__(self) -> None:
        self.now = 0.0

    def __call__(self) -> float:
        return self.now


def reporter():
    logger, clock = Logger(), Clock()
    return ProblemReporter(logger, period_s=2.0, clock=clock), logger, clock


def test_a_different_problem_is_logged_at_once_while_the_first_is_throttled():
    problems, logger, clock = reporter()
    problems.warn('joint_states', 'joint_1 at 10 rad is outside its limits')
    clock.now = 0.3
    problems.warn('joint_states', 'joint_1 at 12 rad is outside its limits')  # same kind
    problems.warn('joint_states', 'expected joints [...], got []')  # another kind
    assert [text for _, text in logger.lines] == [
        'joint_states: joint_1 at 10 rad is outside its limits',
        'joint_states: expected joints [...], got []']
    clock.now = 2.5
    problems.warn('joint_states', 'joint_1 at 13 rad is outside its limits')
    assert logger.lines[-1][1].endswith('(1 more like it since)')
    assert problems.counts['joint_states'] == 4


def test_kinds_mask_values_but_keep_names():
    assert problem_kind('joint_2 at 1e+10 rad, names [a, b]') == \
        problem_kind('joint_2 at -3.5 rad, names [c]')
    assert problem_kind('joint_2 at 1 rad') != problem_kind('joint_3 at 1 rad')


def test_a_guard_rejects_bad_input_and_reports_bugs_without_raising():
    problems, logger, _ = reporter()

    def callback(value):
        if value == 'bad':
            raise InputError('bad value', 'value is bad')
        if value == 'bug':
            raise KeyError('oops')
        return value

    guarded = problems.guard('topic', callback)
    assert guarded('good') == 'good'
    assert guarded('bad') is None and guarded('bug') is None
    assert logger.lines[0] == ('warning', 'topic: rejected: value is bad')
    assert logger.lines[1][0] == 'error' and 'unexpected KeyError' in logger.lines[1][1]
    assert 'Traceback' in logger.lines[1][1] and problems.unexpected == 1


def test_a_guarded_service_answers_a_rejected_request_with_the_reason():
    problems, _, _ = reporter()

    class Response:
        success = True
        message = ''

    def callback(request, response):
        raise ValueError('no task yet')

    response = problems.guard_service('~/start_trial', callback)(None, Response())
    assert response.success is False and response.message == 'no task yet'


@pytest.mark.parametrize('message', ['', 'plain', '1e999 nan inf -inf [1, 2] "x" \'y\''])
def test_problem_kind_accepts_any_text(message):
    assert isinstance(problem_kind(message), str)
