"""Helpers shared by the studies tests (served as fixtures by tests/conftest.py): a two-mode problem
with crossing frequencies, the Mathieu principal tongue, bit-for-bit comparison of results."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
from scipy.optimize import brentq
from scipy.special import mathieu_a, mathieu_b

from studies import PeriodicCoefficients, PeriodicProblem


def crossing_coefficients(values):
    """x1'' + c x1' + (1 + 0.5 W^2) x1 = cos W t,  x2'' + c x2' + (4 - 0.5 W^2) x2 = 0."""
    speed, c = values["speed"], values["damping"]
    k1, k2 = 1.0 + 0.5 * speed**2, 4.0 - 0.5 * speed**2
    return PeriodicCoefficients(period=2 * math.pi / speed, mass=lambda t: np.eye(2),
                                damping=lambda t: c * np.eye(2),
                                stiffness=lambda t: np.diag([k1, k2]),
                                force=lambda t: np.array([math.cos(speed * t), 0.0]))


def crossing_problem(damping=0.02):
    """Two modes whose frequencies cross at speed sqrt(3) (a top-level, picklable problem)."""
    return PeriodicProblem(name="crossing", coefficients=crossing_coefficients,
                           parameter_values=(("speed", 1.0), ("damping", damping)),
                           parameter_units=(("speed", "rad/s"), ("damping", "1/s")),
                           observable_rows=(("x1", "m", (1.0, 0.0)), ("x2", "m", (0.0, 1.0))),
                           labels=("x1", "x2"))


def principal_tongue(w0, epsilon):
    """Speeds bounding the principal (Omega ~ 2 w0) instability tongue of the undamped Mathieu
    equation: with tau = Omega t / 2 it reads y'' + (a - 2 q cos 2 tau) y = 0, a = 4 w0^2 / Omega^2,
    |q| = epsilon a / 2; unstable for b_1(q) < a < a_1(q)."""
    lower = brentq(lambda a: a - float(mathieu_b(1, epsilon * a / 2)), 0.3, 3.0)
    upper = brentq(lambda a: a - float(mathieu_a(1, epsilon * a / 2)), 0.3, 3.0)
    return sorted((2 * w0 / math.sqrt(lower), 2 * w0 / math.sqrt(upper)))


def assert_same(a, b):
    """Two results equal field by field, arrays to the last bit (NaN equal to NaN)."""
    assert type(a) is type(b)
    for field in dataclasses.fields(a):
        if field.name.endswith("run_time"):
            continue
        x, y = getattr(a, field.name), getattr(b, field.name)
        if isinstance(x, np.ndarray):
            assert x.dtype.kind == y.dtype.kind and x.shape == y.shape, field.name
            if x.dtype.kind in "fc":
                np.testing.assert_array_equal(x, y, err_msg=field.name)
            else:
                assert (x == y).all(), field.name
        elif isinstance(x, dict) and x and isinstance(next(iter(x.values())), np.ndarray):
            assert x.keys() == y.keys(), field.name
            for key in x:
                np.testing.assert_array_equal(x[key], y[key], err_msg=f"{field.name}[{key}]")
        elif field.name != "settings":
            np.testing.assert_equal(x, y, err_msg=field.name)  # NaN equals NaN here, also in dicts
