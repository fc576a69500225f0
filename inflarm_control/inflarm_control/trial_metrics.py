"""Per-axis RMSE and reach time of a control trial, accumulated sample by sample (Figs 7-8).

Pure numpy, no rclpy: the pressure controller node feeds it live samples, `run_trials` feeds it
simulated ones, and both report the same numbers.
"""

import numpy as np
import numpy.typing as npt


class TrialMetrics:
    """Accumulates the end-point error of ``n`` tasks over one trial, per axis x, y, z.

    Parameters
    ----------
    target : array-like, shape (3,) or (n, 3)
        Target end point [m].
    tolerance : float
        Reach tolerance per axis [m], > 0.

    Notes
    -----
    RMSE is the root mean square of ``zeta_e - zeta_d`` over every sample (Fig 8). The reach time
    of an axis is the time of the first sample after which the coordinate stays within
    ``tolerance`` of the target up to the latest sample; ``inf`` while the latest is outside.
    """

    def __init__(self, target: npt.ArrayLike, tolerance: float) -> None:
        target = np.asarray(target, dtype=float)
        if target.ndim not in (1, 2) or target.shape[-1] != 3:
            raise ValueError(f'expected target of shape (3,) or (n, 3), got {target.shape}')
        if not np.isfinite(target).all():
            raise ValueError('expected a finite target [m]')
        if not (np.isfinite(tolerance) and tolerance > 0.0):
            raise ValueError(f'expected tolerance > 0 m, got {tolerance}')
        self.target = np.atleast_2d(target)
        self.tolerance = float(tolerance)
        self.samples = 0
        self._counts = np.zeros((self.target.shape[0], 1))
        self._squared = np.zeros(self.target.shape)
        self._outside = np.zeros(self.target.shape, dtype=bool)
        self._inside_since = np.full(self.target.shape, np.inf)

    def add(self, end_point: npt.ArrayLike, time: float,
            valid: npt.ArrayLike | None = None) -> None:
        """Add one sample of the measured end point, shape like ``target``, taken at ``time`` [s]
        from the start of the trial.

        ``valid`` (bool, shape (n,), optional) marks the tasks that have a measurement; the
        others (NaN allowed there) are left out of their RMSE and reach time. Default: all.
        """
        point = np.atleast_2d(np.asarray(end_point, dtype=float))
        if valid is None:
            ok = np.ones((self.target.shape[0], 1), dtype=bool)
        else:
            ok = np.asarray(valid, dtype=bool)
            if ok.shape != (self.target.shape[0],):
                raise ValueError(
                    f'expected valid of shape ({self.target.shape[0]},), got {ok.shape}')
            ok = ok[:, None]
        if point.shape != self.target.shape or not np.isfinite(np.where(ok, point, 0.0)).all():
            raise ValueError(
                f'expected a finite end_point of shape {self.target.shape}, got '
                f'{np.shape(end_point)} {np.asarray(end_point).tolist()}')
        error = np.where(ok, point - self.target, 0.0)
        self._squared += error * error
        self._counts += ok
        self.samples += 1
        outside = np.abs(error) > self.tolerance
        entered = ~outside & (self._outside | np.isinf(self._inside_since))
        inside_since = np.where(outside, np.inf, np.where(entered, time, self._inside_since))
        self._inside_since = np.where(ok, inside_since, self._inside_since)
        self._outside = np.where(ok, outside, self._outside)

    @property
    def rmse(self) -> npt.NDArray[np.float64]:
        """RMSE per axis so far, shape (n, 3) [m]; NaN before a task's first sample."""
        with np.errstate(invalid='ignore', divide='ignore'):
            return np.sqrt(self._squared / self._counts)

    @property
    def reach_time(self) -> npt.NDArray[np.float64]:
        """Reach time per axis so far, shape (n, 3) [s]; ``inf`` if not (or no longer) within
        tolerance at the latest sample."""
        return self._inside_since.copy()
