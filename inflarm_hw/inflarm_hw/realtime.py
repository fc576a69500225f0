"""Steps of a simulation that keeps pace with the wall clock (pure Python, no rclpy).

A simulator node steps its plant from a timer. Stepping by the timer's nominal period lets
simulated time fall behind whenever a callback runs late, e.g. behind a camera frame being
rendered in the same thread (``inflarm_hw/README.md`` has the figure for ``sra_sim``). The
controller's clock does not slow down with it, so the arm appears slower than it is.
`ElapsedSteps` gives the time that really passed instead.
"""

from collections.abc import Callable
import math
import time


class ElapsedSteps:
    """Seconds elapsed on a steady clock since the previous call (the first: since creation).

    Parameters
    ----------
    max_step_s : float
        Longest step returned [s], > 0: after a longer stall (a suspended process) the
        simulation skips the rest rather than integrating it in one step.
    clock : callable, optional
        Steady clock in seconds (default `time.monotonic`).
    """

    def __init__(self, max_step_s: float,
                 clock: Callable[[], float] = time.monotonic) -> None:
        if not (math.isfinite(max_step_s) and max_step_s > 0.0):
            raise ValueError(f'expected max_step_s > 0 s, got {max_step_s}')
        self.max_step_s = float(max_step_s)
        self.clock = clock
        self.last = clock()

    def __call__(self) -> float:
        """The next step [s], in ``[0, max_step_s]``."""
        now = self.clock()
        step = min(max(now - self.last, 0.0), self.max_step_s)
        self.last = now
        return step
