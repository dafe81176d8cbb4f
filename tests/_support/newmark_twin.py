"""A slow, obvious numpy twin of the Newmark kernel ``periodic._newmark.newmark_march``."""

import numpy as np


def newmark_numpy(M, C, K, f, h, beta, gamma, forced, x0, v0):
    """Newmark's scheme written directly from its textbook form, one np.linalg.solve per step."""
    x, v = x0.copy(), v0.copy()
    a = np.linalg.solve(M[0], np.outer(f[0], forced) - C[0] @ v - K[0] @ x)
    xs, vs, as_ = [x], [v], [a]
    for k in range(1, M.shape[0]):
        x_pred = x + h * v + h * h * (0.5 - beta) * a
        v_pred = v + h * (1.0 - gamma) * a
        effective = M[k] + gamma * h * C[k] + beta * h * h * K[k]
        a = np.linalg.solve(effective, np.outer(f[k], forced) - C[k] @ v_pred - K[k] @ x_pred)
        x = x_pred + beta * h * h * a
        v = v_pred + gamma * h * a
        xs.append(x), vs.append(v), as_.append(a)
    return np.array(xs), np.array(vs), np.array(as_)
