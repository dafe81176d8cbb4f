"""A rigid pendulum written by hand in redundant coordinates, for tests of code that works on any
model satisfying ``mechanisms.ConstrainedModel``.

Coordinates ``s = (x, y, theta)`` of the centroid and the body angle; the pivot sits at the body
point ``(-arm, 0)`` and follows a prescribed path ``p(t)``:

    Phi(s, t) = (x, y) - arm * (cos theta, sin theta) - p(t) = 0.

Mass ``mass`` (kg), centroidal inertia ``inertia`` (kg m^2), gravity ``-g`` along y. Its minimal
model is ``(J + m a^2) theta'' + m a (cos theta (p_y'' + g) - sin theta p_x'') = 0``.
"""

from __future__ import annotations

import math

import numpy as np


class CentroidPendulum:
    n_coords = 3
    n_constraints = 2
    coord_labels = ("bob.x", "bob.y", "bob.theta")
    constraint_labels = ("pivot.x", "pivot.y")
    rigid_index = np.array([0, 1, 2])
    elastic_index = np.array([], dtype=np.int64)

    def __init__(self, *, mass=2.0, inertia=0.05, arm=0.4, g=0.0, path=None):
        self.mass, self.inertia, self.arm, self.g = mass, inertia, arm, g
        # path(t) -> (p, p', p'') each (2,)
        self.path = path or (lambda t: (np.zeros(2), np.zeros(2), np.zeros(2)))

    def mass_matrix(self, s):
        return np.diag([self.mass, self.mass, self.inertia])

    def forces(self, s, sdot, t):
        return np.array([0.0, -self.mass * self.g, 0.0])

    def constraints(self, s, t):
        p, _, _ = self.path(t)
        e = np.array([math.cos(s[2]), math.sin(s[2])])
        return s[:2] - self.arm * e - p

    def constraint_jacobian(self, s, t):
        c, sn = math.cos(s[2]), math.sin(s[2])
        return np.array([[1.0, 0.0, self.arm * sn], [0.0, 1.0, -self.arm * c]])

    def constraint_rate(self, s, t):
        _, pd, _ = self.path(t)
        return -pd

    def constraint_gamma(self, s, sdot, t):
        _, _, pdd = self.path(t)
        c, sn = math.cos(s[2]), math.sin(s[2])
        w2 = sdot[2] ** 2
        return np.array([-self.arm * c * w2, -self.arm * sn * w2]) + pdd

    def mass_matrix_jacobian(self, s, sddot):
        return np.zeros((3, 3))

    def force_jacobians(self, s, sdot, t):
        return np.zeros((3, 3)), np.zeros((3, 3))

    def constraint_force_jacobian(self, s, lam, t):
        c, sn = math.cos(s[2]), math.sin(s[2])
        out = np.zeros((3, 3))
        out[2, 2] = self.arm * (c * lam[0] + sn * lam[1])
        return out

    def kinetic_energy(self, s, sdot):
        return 0.5 * sdot @ self.mass_matrix(s) @ sdot

    def potential_energy(self, s):
        return self.mass * self.g * s[1]

    # --- nominal motions with closed forms, for the tests --------------------------------------
    def hanging_nominal(self, period, n_steps):
        """Rigid nominal motion hanging below the moving pivot (theta = -pi/2), with multipliers
        from the rigid inverse dynamics: arrays t, s, sdot, sddot, lam."""
        t = np.linspace(0.0, period, n_steps + 1)
        s = np.zeros((t.size, 3))
        sd = np.zeros_like(s)
        sdd = np.zeros_like(s)
        lam = np.zeros((t.size, 2))
        for k, tk in enumerate(t):
            p, pd, pdd = self.path(tk)
            s[k] = [p[0], p[1] - self.arm, -math.pi / 2]
            sd[k, :2], sdd[k, :2] = pd, pdd
            lam[k] = -self.mass * (pdd + np.array([0.0, self.g]))
        return t, s, sd, sdd, lam
