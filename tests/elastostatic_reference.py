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
