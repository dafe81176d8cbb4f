"""A pinned-pinned column under a gravity end load: the Euler-buckling reference of the linearisation
and linear-range tests (shared here so that no test module imports another)."""

from __future__ import annotations

import math

import mechanisms as mc


def euler_column(load_ratio, discretisation):
    """A pinned-pinned steel column carrying a heavy point mass on a vertical slider, loaded by
    gravity: end load P = load_ratio * P_Euler. A rigid crank at rest only supplies the drive that
    every mechanism needs. The column's own weight is 1e-6 of P."""
    column = mc.ElasticLink.rectangular("column", 0.5, width=0.02, thickness=0.002, density=7800.0,
                                       youngs_modulus=2.0e11, discretisation=discretisation)
    euler_load = math.pi**2 * column.youngs_modulus * column.second_moment / column.length**2
    mass = 1e6 * column.mass
    base = mc.RigidLink.uniform("base", 0.1, width=0.02, thickness=0.002, density=7800.0)
    mechanism = mc.Mechanism(
        name="column", links=(base, column),
        joints=(mc.Revolute("O", "ground", (0.0, 0.0), "base", "start"),
                mc.Revolute("A", "base", "end", "column", "start"),
                mc.Slider("top", "column", "end", origin=(0.1, 0.0), angle=math.pi / 2)),
        drives=(mc.PrescribedDrive("O", rate=0.0),),
        point_masses=(mc.PointMass("column", "end", mass),),
        gravity=(0.0, -load_ratio * euler_load / mass),
        initial_angles={"base": 0.0, "column": math.pi / 2}, period=1.0)
    return mechanism, column
