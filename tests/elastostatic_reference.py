"""Independent ground truth for the elastostatic tests.

The spring equilibrium k q_k = U_k^T f solved with ``scipy.optimize.root`` on the textbook DH
chain (``dh_jacobian_reference``): no Pinocchio and none of the solvers under test.
"""

import numpy as np
from scipy.optimize import root

from inflarm_model.elastostatics import MOTOR_INDICES, SPRING_INDICES
from inflarm_model.kinematics import dh_jacobian_reference

K_MEAN = 172.71  # k̄ of section 4 [N·m/rad]
M, K = list(MOTOR_INDICES), list(SPRING_INDICES)


def full_q(q_m, q_k) -> np.ndarray:
    q = np.zeros(7)
    q[M], q[K] = q_m, q_k
    return q


def reference_deflections(arm, q_m, force, k, max_residual: float) -> np.ndarray:
    """Spring deflections q_k (4,) holding ``force``; asserts the solve's residual [N·m]."""
    k = np.broadcast_to(np.asarray(k, dtype=float), (4,))

    def residual(q_k):
        U = dh_jacobian_reference(arm.dh_table, full_q(q_m, q_k))[:3]
        return k * q_k - U[:, K].T @ force

    sol = root(residual, np.zeros(4), method='hybr', tol=1e-14)
    assert np.abs(residual(sol.x)).max() < max_residual
    return sol.x


def smooth_motion(rng, samples: int, duration: float, max_force: float):
    """A seeded smooth motion: motor angles (samples, 3) [rad] within the motor limits, each a
    sum of two sinusoids, and a tip load (samples, 3) [N] whose magnitude ramps from 0 to
    ``max_force`` while its direction turns slowly."""
    t = np.linspace(0.0, duration, samples)[:, None]
    center = rng.uniform([-2.0, -0.8, -1.8], [2.0, 0.8, 1.8])
    amplitude = rng.uniform([0.2, 0.1, 0.1], [0.8, 0.5, 0.6])
    frequency = rng.uniform(0.05, 0.3, (2, 3))
    phase = rng.uniform(0.0, 2 * np.pi, (2, 3))
    q_m = center + amplitude * 0.5 * (np.sin(2 * np.pi * frequency[0] * t + phase[0])
                                      + np.sin(2 * np.pi * frequency[1] * t + phase[1]))
    q_m = np.clip(q_m, [-np.pi, -np.pi / 2, -2.6], [np.pi, np.pi / 2, 2.6])
    axis_a, axis_b = rng.normal(size=(2, 3))
    turn = rng.uniform(0.2, 1.0) * t / duration
    direction = np.cos(turn) * axis_a + np.sin(turn) * axis_b
    direction /= np.linalg.norm(direction, axis=1, keepdims=True)
    return q_m, direction * max_force * (t / duration)


def reference_motion(arm, q_m, forces, k, max_residual: float = 1e-10):
    """Independent truth along a motion: the spring deflections (N, 4) by continuation in
    time (``scipy.optimize.root`` on the textbook DH chain, each sample from the previous
    one) and the motor torques tau_m = U_m^T f (N, 3)."""
    k = np.broadcast_to(np.asarray(k, dtype=float), (4,))
    q_k = np.zeros(4)
    Q_k, Tau = np.empty((len(q_m), 4)), np.empty((len(q_m), 3))
    for i, (motors, force) in enumerate(zip(q_m, forces, strict=True)):
        def residual(x, motors=motors, force=force):
            U = dh_jacobian_reference(arm.dh_table, full_q(motors, x))[:3]
            return k * x - U[:, K].T @ force

        q_k = root(residual, q_k, method='hybr', tol=1e-14).x
        assert np.abs(residual(q_k)).max() < max_residual
        U = dh_jacobian_reference(arm.dh_table, full_q(motors, q_k))[:3]
        Q_k[i], Tau[i] = q_k, U[:, M].T @ force
    return Q_k, Tau


def reference_loads(arm, q_m, tau_m, k, rng, starts: int = 200, max_force: float = 150.0):
    """Independent multi-start search for the admissible loads that give these torques.

    ``scipy.optimize.root`` on the full 7-equation system (U_m^T f = tau_m, k q_k = U_k^T f)
    of the textbook chain from ``starts`` random (f, q_k), f from the rigid solve at a random
    q_k in the model range; keeps the distinct solutions with |q_k| < pi/2, |f| <= max_force
    and a stable equilibrium (K - H_kk positive definite, H by central differences). Returns
    a list of (force (3,), q_k (4,)).
    """
    k = np.broadcast_to(np.asarray(k, dtype=float), (4,))

    def residual(x):
        U = dh_jacobian_reference(arm.dh_table, full_q(q_m, x[3:]))[:3]
        return np.concatenate([U[:, M].T @ x[:3] - tau_m, k * x[3:] - U[:, K].T @ x[:3]])

    def stable(f, q_k, h=1e-6):
        def spring_torque(x):
            return dh_jacobian_reference(arm.dh_table, full_q(q_m, x))[:3, K].T @ f

        H = np.array([(spring_torque(q_k + h * e) - spring_torque(q_k - h * e)) / (2 * h)
                      for e in np.eye(4)])
        return np.linalg.eigvalsh(np.diag(k) - 0.5 * (H + H.T))[0] > 0.0

    found = []
    for _ in range(starts):
        q_k0 = rng.uniform(-np.pi / 2, np.pi / 2, 4) * rng.uniform(0.0, 1.0)
        U = dh_jacobian_reference(arm.dh_table, full_q(q_m, q_k0))[:3]
        try:
            f0 = np.linalg.solve(U[:, M].T, tau_m)
        except np.linalg.LinAlgError:
            continue
        x = root(residual, np.concatenate([f0, q_k0]), method='hybr', tol=1e-13).x
        if (np.abs(residual(x)).max() > 1e-8 or np.abs(x[3:]).max() >= np.pi / 2
                or np.linalg.norm(x[:3]) > max_force or not stable(x[:3], x[3:])):
            continue
        if all(np.abs(x[3:] - q).max() > 1e-6 for _, q in found):
            found.append((x[:3], x[3:]))
    return found
