"""A simulated MCU on a real pty, run by a thread of the test process (no ROS)."""

import threading
import time

import numpy as np

from inflarm_hw.inflatable_arm_sim import InflatableArmSim
from inflarm_hw.sim_mcu import McuPort, SimMcu, SimMcuParams
from inflarm_hw.sra_plant import SoftArmPlant
from inflarm_model.kinematics import FlexibleArm

LOAD = [0.0, 10.0, -15.0]
Q0 = [0.0, 0.6, -1.2]


def make_mcu(plants: str = 'both', **params) -> SimMcu:
    rng = np.random.default_rng(7)
    arm = sra = None
    if plants in ('arm', 'both'):
        arm = InflatableArmSim(FlexibleArm(0.6, 0.03), 172.71, [50e3, 50e3], 0.055, Q0, rng=rng)
        arm.set_tip_force(LOAD)
    if plants in ('sra', 'both'):
        sra = SoftArmPlant(1, rng=rng)
    return SimMcu(arm, sra, [50e3, 50e3], SimMcuParams(**params), rng)


class ManualClock:
    """A steady clock [s] that moves only when the test moves it (a driver's ``clock``)."""

    def __init__(self, start_s: float = 100.0) -> None:
        self.now_s = start_s

    def __call__(self) -> float:
        return self.now_s

    def advance(self, dt_s: float) -> None:
        self.now_s += dt_s


class McuThread:
    """Runs ``mcu`` behind a new pty: bytes in as they come, a step every 1 / rate_hz."""

    def __init__(self, mcu: SimMcu, rate_hz: float = 100.0) -> None:
        self.mcu = mcu
        self.port = McuPort()
        self.path = self.port.path
        self.lock = threading.Lock()
        self.dt = 1.0 / rate_hz
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)
        self._thread.start()

    def _run(self) -> None:
        next_step = time.monotonic()
        while not self._stop.is_set():
            now = time.monotonic()
            with self.lock:
                data = self.port.read()
                if data:
                    self.port.write(self.mcu.receive(data, now))
                if now >= next_step:
                    self.port.write(self.mcu.step(self.dt, now))
                    next_step += self.dt
            time.sleep(0.001)

    def inject(self, *args) -> None:
        with self.lock:
            self.mcu.inject(*args, time.monotonic())

    def close(self) -> None:
        self._stop.set()
        self._thread.join(timeout=5.0)
        self.port.close()
