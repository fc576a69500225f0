"""A session of PID + ILC pressure control of the soft arm, without ROS (Fig 6 of 001_...).

`PressureControlSession` is what the ``pressure_controller`` node runs between its topics: it
takes the measured end point (`measure`), tasks (`start_task`), planned paths (`follow`) and
alert regions, and on every control step (`step`) gives the chamber set pressures to publish
and, when a trial ends, its report.

A trial drives the end from where it is to a target: every step runs the three axis controllers
(`inflarm_control.pid_ilc.PidIlcController`) on the latest measurement. After the trial's
duration its outputs become the ILC memory of that target (seeding the next ``pid_ilc`` trial
to it) and the last pressures are held. Without a memory, a ``pid_ilc`` task is seeded from
the experiential knowledge database when there is one. A path is followed by
`inflarm_control.path_following.PathFollower`, its end then held under control. A measurement
older than the timeout is a vision dropout: the step holds the pressures and teaches nothing.

ILC memories are kept per target, to the millimetre, and in a file (`save_ilc_memories`) when
the session has one, so that learning carries over between runs.
"""

from dataclasses import dataclass
import math
import os
from pathlib import Path

import numpy as np
import numpy.typing as npt

from inflarm_control.knowledge import KnowledgeDatabase, holding_pressure, seed_memory
from inflarm_control.path_following import PathFollower, PathFollowingParams
from inflarm_control.pid_ilc import PidIlcController, PidIlcParams
from inflarm_control.trial_metrics import TrialMetrics
from inflarm_model.soft_arm import CHAMBERS, Workspace, check_in_workspace
from inflarm_msgs_json import ControlTask, TrialReport

__all__ = ['PressureControlSession', 'SessionStep', 'TrialLimits', 'load_ilc_memories',
           'save_ilc_memories', 'task_key']

#: An ILC memory's key: its target to the millimetre.
TaskKey = tuple[int, int, int]


def task_key(target: npt.ArrayLike) -> TaskKey:
    """The key of the ILC memory of ``target`` [m]: the target in whole millimetres."""
    return tuple(int(v) for v in np.round(np.asarray(target) * 1000.0))


def load_ilc_memories(path: str | Path, memory_steps: int) -> dict[TaskKey, np.ndarray]:
    """ILC memories from a file of `save_ilc_memories`; none when ``path`` does not exist.

    Raises
    ------
    ValueError
        If the file is not one of ILC memories of ``memory_steps`` steps.
    """
    if not os.path.exists(path):
        return {}
    try:
        with np.load(path) as data:
            keys, memories = data['targets_mm'], data['memories']
        shape = (len(keys), memory_steps, len(CHAMBERS))
        if keys.shape != (len(keys), 3) or memories.shape != shape:
            raise ValueError(f'arrays of shape {keys.shape} and {memories.shape}')
    except (OSError, KeyError, ValueError) as err:
        raise ValueError(f"ILC memories: '{path}' is not an ILC memory file: {err}") from err
    return {tuple(int(v) for v in key): memory
            for key, memory in zip(keys, memories, strict=True)}


def save_ilc_memories(path: str | Path, memories: dict[TaskKey, np.ndarray],
                      memory_steps: int) -> None:
    """Write ``memories`` to ``path`` (.npz: ``targets_mm`` (M, 3), ``memories`` (M, steps,
    chambers) [Pa]), replacing the file atomically: a crash never leaves half a file."""
    keys = np.array(list(memories), dtype=np.int64).reshape(-1, 3)
    values = np.array(list(memories.values())).reshape(-1, memory_steps, len(CHAMBERS))
    tmp = f'{path}.tmp.npz'
    np.savez(tmp, targets_mm=keys, memories=values)
    os.replace(tmp, path)


@dataclass(frozen=True)
class TrialLimits:
    """How long a trial lasts and what counts as fresh and as reached.

    Attributes
    ----------
    trial_duration : float
        Length of a trial [s].
    measurement_timeout : float
        A measurement older than this is a dropout: hold, do not learn [s].
    reach_tolerance : float
        Per-axis tolerance of the reach time [m].
    """

    trial_duration: float = 20.0
    measurement_timeout: float = 0.5
    reach_tolerance: float = 0.005


@dataclass(frozen=True)
class SessionStep:
    """What a control step gives.

    Attributes
    ----------
    command : ndarray, shape (chambers,), or None
        Set pressures to publish [Pa] (held ones when idle); None before any.
    report : TrialReport or None
        The report of the trial that ended at this step.
    stale : bool
        The latest measurement was too old to act on (pressures held, nothing learned).
    path_end : bool
        The path being followed reached its end at this step.
    """

    command: np.ndarray | None
    report: TrialReport | None = None
    stale: bool = False
    path_end: bool = False


class PressureControlSession:
    """Trials and paths on the soft arm from the latest measured end point.

    Parameters
    ----------
    params : PidIlcParams
        The trial controller's parameters (its rate is the step rate).
    following : PathFollowingParams
        The path follower's.
    limits : TrialLimits
        Trial length, measurement timeout, reach tolerance; `limits` may be replaced between
        steps.
    workspace_margin : float
        Measurements farther than this outside the work space are rejected [m].
    memory_path : str or Path, optional
        File keeping the ILC memories across runs (read now, written after every trial).
    knowledge : KnowledgeDatabase, optional
        Seeds new ``pid_ilc`` tasks and gives a path's feedforward.

    Raises
    ------
    ValueError
        If ``memory_path`` is not an ILC memory file of these parameters.
    """

    def __init__(self, params: PidIlcParams, following: PathFollowingParams,
                 limits: TrialLimits = TrialLimits(), workspace_margin: float = 0.05,
                 memory_path: str | Path | None = None,
                 knowledge: KnowledgeDatabase | None = None) -> None:
        self.params = params
        self.limits = limits
        self.dt = 1.0 / params.rate_hz
        self.controller = PidIlcController(n=1, params=params)
        self.follower = PathFollower(following)
        self.knowledge = knowledge
        self.memory_path = memory_path
        self.memories = load_ilc_memories(memory_path, params.memory_steps) if memory_path \
            else {}
        w = params.workspace
        m = workspace_margin
        self.measurable = Workspace(f'{w.name}, grown by {m} m', w.x_max + m, w.y_max + m,
                                    w.z_min - m, w.z_max + m)

        self.position: np.ndarray | None = None
        self.position_time_ns: int | None = None
        self.task: ControlTask | None = None
        self.trial_active = False
        self.trial_steps = 0
        self.metrics: TrialMetrics | None = None
        self.following = False  # a path is being followed (or its end held)
        self.command: np.ndarray | None = None  # last set pressures, held when idle

    # -- inputs --------------------------------------------------------------------------------

    def measure(self, point: npt.ArrayLike, time_ns: int) -> None:
        """Take a measured end point [m] made at ``time_ns``; ValueError if outside the grown
        work space (a bad measurement: it reaches neither a report nor a memory)."""
        point = np.asarray(point, dtype=float)
        check_in_workspace(point, self.measurable, 'ball_position')
        self.position = point
        self.position_time_ns = time_ns

    def set_alert_regions(self, regions: npt.ArrayLike) -> None:
        """The alert regions a followed path repels the end from, shape (K, 2, 3) [m]
        (`inflarm_model.alert_regions`)."""
        self.follower.set_alert_regions(regions)

    def start_task(self, task: ControlTask) -> tuple[str, str | None]:
        """Start a trial of ``task`` from the current position, its outputs starting at the
        held pressures; ends any path (even when it is rejected). Returns what seeds it
        (``'ILC memory'``, ``'knowledge database'`` or ``'PID alone'``) and why the knowledge
        could not, if it could not.

        Raises
        ------
        ValueError
            If there is no measurement yet or the controller rejects the task.
        """
        self.following = False
        if self.position is None:
            raise ValueError(f'task to {list(task.target)} rejected: no ball_position '
                             'received yet')
        target = np.array(task.target)
        memory, source, problem = None, 'PID alone', None
        if task.mode == 'pid_ilc' and task_key(target) in self.memories:
            memory, source = self.memories[task_key(target)], 'ILC memory'
        elif task.mode == 'pid_ilc' and self.knowledge is not None:
            try:
                memory, source = seed_memory(self.knowledge, target), 'knowledge database'
            except (KeyError, ValueError) as err:
                problem = f'no knowledge for this task: {err}'
        try:
            self.controller.start_trial(self.position, target, memory,
                                        initial_output=self.held())
        except ValueError as err:
            raise ValueError(f'task to {list(task.target)} rejected: {err}') from None
        self.task = task
        self.trial_active = True
        self.trial_steps = 0
        self.metrics = TrialMetrics(target, self.limits.reach_tolerance)
        return source, problem

    def repeat_task(self) -> tuple[ControlTask, str, str | None]:
        """Start the last task again as the next trial (`start_task`'s results with it).

        Raises
        ------
        ValueError
            If there was no task yet, or as `start_task`.
        """
        if self.task is None:
            raise ValueError('no task yet: publish a control_task')
        task = ControlTask(frame_id=self.task.frame_id, target=self.task.target,
                           mode=self.task.mode, trial_id=self.task.trial_id + 1)
        return (task, *self.start_task(task))

    def follow(self, waypoints: npt.ArrayLike) -> tuple[str, str | None]:
        """Follow a path of waypoints (M, 3) [m] from the current position and the held
        pressures, ending any trial. Returns the feedforward's source and why the knowledge
        gave none, if it did not.

        Raises
        ------
        ValueError
            If a waypoint is outside the work space or there is no measurement yet.
        """
        waypoints = np.asarray(waypoints, dtype=float)
        check_in_workspace(waypoints, self.params.workspace, 'waypoint')
        if self.position is None:
            raise ValueError('path rejected: no ball_position received yet')
        feedforward, source, problem = None, 'PI alone', None
        if self.knowledge is not None:
            try:
                feedforward = np.array([holding_pressure(self.knowledge, w) for w in waypoints])
                source = 'knowledge database feedforward'
            except (KeyError, ValueError) as err:
                problem = f'no knowledge along the path ({err}): PI alone'
        held = self.held()
        self.stop()
        self.follower.start(waypoints, self.position, held, feedforward)
        self.following = True
        return source, problem

    # -- control -------------------------------------------------------------------------------

    def held(self) -> np.ndarray:
        """The set pressures held now [Pa] (0 before any)."""
        return np.zeros(len(CHAMBERS)) if self.command is None else self.command

    def fresh(self, now_ns: int) -> bool:
        """Whether the latest measurement is recent enough at ``now_ns`` to act on."""
        return (self.position_time_ns is not None
                and (now_ns - self.position_time_ns) * 1e-9 <= self.limits.measurement_timeout)

    def step(self, now_ns: int) -> SessionStep:
        """One control step at ``now_ns`` (the clock of `measure`'s times)."""
        if self.following:
            was_at_end = self.follower.at_end
            fresh = self.fresh(now_ns)
            self.command = self.follower.step(self.position, self.dt, valid=fresh)
            return SessionStep(self.command, stale=not fresh,
                               path_end=self.follower.at_end and not was_at_end)
        if not self.trial_active:
            return SessionStep(self.command)  # hold: the MCU vents a silent controller
        fresh = self.fresh(now_ns)
        position = self.position if fresh else np.full(3, np.nan)
        self.command = self.controller.step(position[None, :], self.dt, valid=[fresh])[0]
        self.trial_steps += 1
        elapsed = self.trial_steps * self.dt
        if fresh:
            self.metrics.add(self.position, elapsed)
        report = self._finish_trial() if elapsed >= self.limits.trial_duration else None
        return SessionStep(self.command, report, stale=not fresh)

    def _finish_trial(self) -> TrialReport:
        memory = self.controller.finish_trial()[0]
        self.trial_active = False
        self.memories[task_key(self.controller.target[0])] = memory
        self._save_memories()
        reach = [None if math.isinf(t) else float(t) for t in self.metrics.reach_time[0]]
        return TrialReport(trial_index=self.task.trial_id,
                           rmse=tuple(np.nan_to_num(self.metrics.rmse[0])),
                           reach_time=tuple(reach))

    def stop(self) -> None:
        """End a trial without learning (an aborted trial teaches nothing) or a path; the
        pressures stay held."""
        if self.trial_active:
            self.controller.finish_trial()
            self.trial_active = False
        self.following = False

    def vent(self) -> np.ndarray:
        """`stop`, then hold every chamber at 0 Pa (the arm returns to rest): the command."""
        self.stop()
        self.command = np.zeros(len(CHAMBERS))
        return self.command

    def reset_learning(self) -> int:
        """Forget every ILC memory (and the file's); how many there were."""
        count = len(self.memories)
        self.memories.clear()
        self._save_memories()
        return count

    def _save_memories(self) -> None:
        if self.memory_path:
            save_ilc_memories(self.memory_path, self.memories, self.params.memory_steps)
