"""Bad input reported, never raised: callback guards and warnings throttled per kind of problem.

Every subscription, service and timer callback of an inflarm node is wrapped by
`ProblemReporter.guard`: a ``ValueError`` (``InputError``, ``MessageError`` and the cores'
argument checks are all ValueErrors) rejects the input with a warning naming the problem; any
other exception is a bug, logged as an error with its traceback and counted in ``unexpected``;
in both cases the node keeps running. Warnings are throttled per *kind* of problem, so a second,
different problem is logged at once even if the first one is still being throttled.

    self.problems = ProblemReporter(self.get_logger())
    self.create_subscription(JointState, 'joint_states',
                             self.problems.guard('joint_states', self.on_joint_states), qos)
    ...
    raise InputError('unknown joint', f"unknown joints {names}, expected {MOTORS}")
"""

from collections.abc import Callable
from dataclasses import dataclass
import functools
import re
import time
import traceback

DEFAULT_PERIOD_S = 2.0

# What makes two messages the same kind of problem when no kind is given: their text with the
# values masked (numbers, quoted names, bracketed lists).
_VALUES = re.compile(
    r"'[^']*'|\"[^\"]*\"|\[[^\]]*\]"  # quoted names, bracketed lists
    r'|(?<!\w)[-+]?(?:\d+(?:\.\d*)?(?:e[-+]?\d+)?|\.\d+|nan|inf(?:inity)?)(?!\w)',  # numbers
    re.IGNORECASE)


class InputError(ValueError):
    """Input that a node rejects; ``kind`` (e.g. ``'unknown joint'``) groups warnings."""

    def __init__(self, kind: str, message: str) -> None:
        super().__init__(message)
        self.kind = kind


def problem_kind(message: str) -> str:
    """The kind of a problem message: its text with the values masked."""
    return _VALUES.sub('#', message)


@dataclass
class _Throttle:
    last_logged: float
    suppressed: int = 0


class ProblemReporter:
    """Logs problems through ``logger``, at most once per ``period_s`` for each kind.

    Attributes
    ----------
    counts : dict[str, int]
        Problems seen per source (topic, service or timer name), logged or not.
    unexpected : int
        Exceptions other than ValueError caught by a guard: bugs.
    last : dict[str, str]
        The latest problem message per source.
    """

    def __init__(self, logger, period_s: float = DEFAULT_PERIOD_S,
                 clock: Callable[[], float] = time.monotonic) -> None:
        self.logger = logger
        self.period_s = period_s
        self.clock = clock
        self.counts: dict[str, int] = {}
        self.last: dict[str, str] = {}
        self.unexpected = 0
        self._throttles: dict[tuple[str, str], _Throttle] = {}

    def _due(self, source: str, kind: str) -> tuple[bool, int]:
        """Whether this kind is due to be logged, and how many were suppressed since."""
        now = self.clock()
        throttle = self._throttles.get((source, kind))
        if throttle is None:
            self._throttles[(source, kind)] = _Throttle(now)
            return True, 0
        if now - throttle.last_logged >= self.period_s:
            suppressed, throttle.suppressed, throttle.last_logged = throttle.suppressed, 0, now
            return True, suppressed
        throttle.suppressed += 1
        return False, 0

    def _record(self, source: str, message: str) -> None:
        self.counts[source] = self.counts.get(source, 0) + 1
        self.last[source] = message

    def warn(self, source: str, message: str, kind: str | None = None) -> None:
        """Warn about ``message`` from ``source``, throttled per (source, kind)."""
        self._record(source, message)
        due, suppressed = self._due(source, kind or problem_kind(message))
        if due:
            more = f' ({suppressed} more like it since)' if suppressed else ''
            self.logger.warning(f'{source}: {message}{more}')

    def reject(self, source: str, error: ValueError) -> None:
        """Warn that input on ``source`` was rejected, and why."""
        self.warn(source, f'rejected: {error}', getattr(error, 'kind', None))

    def bug(self, source: str, error: Exception) -> None:
        """Log an unexpected exception with its traceback (throttled per exception type)."""
        self.unexpected += 1
        message = f'unexpected {type(error).__name__}: {error}'
        self._record(source, message)
        due, suppressed = self._due(source, f'bug {type(error).__name__}')
        if due:
            more = f' ({suppressed} more since)' if suppressed else ''
            trace = ''.join(traceback.format_exception(error)).rstrip()
            self.logger.error(f'{source}: {message}{more}; the node keeps running\n{trace}')

    def guard(self, source: str, callback: Callable) -> Callable:
        """``callback`` for a subscription or timer, with nothing escaping it."""
        @functools.wraps(callback)
        def guarded(*args):
            try:
                return callback(*args)
            except ValueError as error:
                self.reject(source, error)
            except Exception as error:  # noqa: BLE001 (a callback must never kill the node)
                self.bug(source, error)
            return None
        return guarded

    def guard_service(self, source: str, callback: Callable) -> Callable:
        """``callback(request, response)`` for a service: a rejected request is answered, with
        ``success = False`` and the reason in ``message`` where the response has them."""
        @functools.wraps(callback)
        def guarded(request, response):
            try:
                return callback(request, response)
            except ValueError as error:
                self.reject(source, error)
                reason = str(error)
            except Exception as error:  # noqa: BLE001
                self.bug(source, error)
                reason = f'internal error: {type(error).__name__}: {error}'
            if hasattr(response, 'success'):
                response.success = False
            if hasattr(response, 'message'):
                response.message = reason
            return response
        return guarded
