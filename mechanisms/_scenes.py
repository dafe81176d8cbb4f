"""Builders for the shipped scenes, in Python, with keyword-only parameters.

Each builder writes a scene spec (the same tables as the TOML files in ``mechanisms/scenes/``,
documented in ``docs/scenes.md``) and builds it, so the result keeps its spec and
``with_parameter`` works on it exactly as on a loaded scene. With default arguments each builder
equals its shipped scene (tested).
"""

from __future__ import annotations

import math
from typing import Any

from ._load import build
from ._parts import Mechanism, MechanismError

STEEL = {"density": 7800.0, "youngs_modulus": 2.0e11}      # kg/m^3, Pa
ALUMINIUM = {"density": 2700.0, "youngs_modulus": 7.0e10}  # kg/m^3, Pa


def _upper_intersection(p: tuple[float, float], r_p: float, q: tuple[float, float],
                        r_q: float) -> tuple[float, float]:
    """The intersection of circles (p, r_p) and (q, r_q) to the left of p -> q (the open branch
    with the linkage above a ground line drawn left to right)."""
    dx, dy = q[0] - p[0], q[1] - p[1]
    d = math.hypot(dx, dy)
    if not abs(r_p - r_q) < d < r_p + r_q:
        raise MechanismError(f"the links of lengths {r_p:.6g} and {r_q:.6g} m cannot close over "
                             f"{d:.6g} m at the initial crank angle")
    a = (r_p**2 - r_q**2 + d**2) / (2.0 * d)
    h = math.sqrt(r_p**2 - a**2)
    return (p[0] + (a * dx - h * dy) / d, p[1] + (a * dy + h * dx) / d)


def _angle(p: tuple[float, float], q: tuple[float, float]) -> float:
    # Rounded: initial angles only pick the assembly branch, and rounding keeps scene files legible.
    return round(math.atan2(q[1] - p[1], q[0] - p[0]), 4)


def _elastic(length: float, *, width: float, thickness: float, material: dict[str, float],
             discretisation: dict[str, Any], damping_ratio: float, geometric_stiffening: bool,
             boundary: str = "pinned-pinned", axial: bool = True,
             rotary_inertia: bool = False) -> dict[str, Any]:
    return {"type": "elastic", "length": length, "width": width, "thickness": thickness,
            **material, "discretisation": discretisation, "boundary": boundary, "axial": axial,
            "geometric_stiffening": geometric_stiffening, "rotary_inertia": rotary_inertia,
            "damping": {"type": "rayleigh", "ratio": damping_ratio}}


def _discretisation(discretisation: str, n_elements: int, n_bending: int,
                    n_axial: int) -> dict[str, Any]:
    if discretisation == "fem":
        return {"type": "fem", "n_elements": n_elements}
    if discretisation == "ritz":
        return {"type": "ritz", "n_bending": n_bending, "n_axial": n_axial}
    raise MechanismError(f"discretisation must be 'fem' or 'ritz', got {discretisation!r}")


def four_bar(*, discretisation: str = "fem", n_elements: int = 4, n_bending: int = 2,
             n_axial: int = 1, crank_speed: float = 100.0, ground: float = 0.254,
             crank: float = 0.0508, coupler: float = 0.2794, rocker: float = 0.2794,
             width: float = 0.020, thickness: float = 0.0016, density: float = 7800.0,
             youngs_modulus: float = 2.0e11, damping_ratio: float = 0.02,
             geometric_stiffening: bool = True, axial: bool = True, rotary_inertia: bool = False,
             gravity: tuple[float, float] = (0.0, 0.0), name: str | None = None) -> Mechanism:
    """The thesis four-bar OABC (seed Fig. 2.5): rigid uniform crank OA and rocker CB, elastic
    coupler AB, all of section ``width x thickness`` (m) bending about the thin direction.

    Lengths in m, ``crank_speed`` in rad/s (crank angle ``crank_speed * t`` from the x-axis),
    ``damping_ratio`` of stiffness-proportional damping at the coupler's first pinned-pinned bending
    frequency (beta = 2 zeta / omega_1). ``geometric_stiffening=False`` with ``discretisation="ritz"``
    is the seed's energy expressions exactly (scene ``four_bar_thesis``).
    """
    o, c = (0.0, 0.0), (ground, 0.0)
    a = (crank, 0.0)
    b = _upper_intersection(a, coupler, c, rocker)
    material = {"density": density, "youngs_modulus": youngs_modulus}
    bar = {"type": "rigid", "width": width, "thickness": thickness, "density": density}
    parts = _discretisation(discretisation, n_elements, n_bending, n_axial)
    default_name = ("four_bar_ritz" if discretisation == "ritz"
                    else f"four_bar_fem{n_elements}")
    spec = {
        "name": name or default_name,
        "gravity": list(gravity),
        "initial_angles": {"crank": 0.0, "coupler": _angle(a, b), "rocker": _angle(c, b)},
        "links": {
            "crank": {**bar, "length": crank},
            "coupler": _elastic(coupler, width=width, thickness=thickness, material=material,
                                discretisation=parts, damping_ratio=damping_ratio,
                                geometric_stiffening=geometric_stiffening, axial=axial,
                                rotary_inertia=rotary_inertia),
            "rocker": {**bar, "length": rocker},
        },
        "joints": {
            "O": {"type": "revolute", "link_a": "ground", "point_a": list(o), "link_b": "crank",
                  "point_b": "start"},
            "A": {"type": "revolute", "link_a": "crank", "point_a": "end", "link_b": "coupler",
                  "point_b": "start"},
            "B": {"type": "revolute", "link_a": "coupler", "point_a": "end", "link_b": "rocker",
                  "point_b": "end"},
            "C": {"type": "revolute", "link_a": "ground", "point_a": list(c), "link_b": "rocker",
                  "point_b": "start"},
        },
        "drive": {"type": "prescribed", "joint": "O", "rate": crank_speed},
    }
    return build(spec, source="four_bar()")


def six_bar(*, crank_speed: float = 100.0, n_elements: int = 2, width: float = 0.020,
            thickness: float = 0.002, density: float = 7800.0, youngs_modulus: float = 2.0e11,
            damping_ratio: float = 0.02, geometric_stiffening: bool = True,
            name: str = "six_bar") -> Mechanism:
    """The Watt II six-bar of the seed's Fig. 1.2: crank 1 (O1A), elastic link 2 (AB), rigid plate 3
    pivoted at O2 carrying B and C, elastic link 4 (CD), rigid output rocker 5 (O3D).

    Dimensions (m): O1O2 = 0.30, O1A = 0.06, AB = 0.28, O2B = 0.15 (loop 1); O2O3 = 0.30, O2C = 0.10
    at 60 deg from O2B on the plate, CD = 0.30, O3D = 0.20 (loop 2). Both loops are Grashof with
    their input the shortest link (0.06 + 0.30 <= 0.28 + 0.15 and 0.10 + 0.30 <= 0.30 + 0.20), so
    the crank turns fully, the plate rocks, and the second loop has no toggle for any plate angle.
    Elastic links of section ``width x thickness``, ``n_elements`` FEM elements each.
    """
    o1, o2, o3 = (0.0, 0.0), (0.30, 0.0), (0.60, 0.0)
    l1, l2, l3b, l3c, l4, l5 = 0.06, 0.28, 0.15, 0.10, 0.30, 0.20
    plate_thickness, c_angle = 0.006, -math.radians(60.0)
    point_c = (l3c * math.cos(c_angle), l3c * math.sin(c_angle))
    # Triangular steel plate O2-B-C: mass rho t area, centroid at the mean of its corners, polar
    # moment about the centroid m (a^2 + b^2 + c^2) / 36 for sides a, b, c.
    corners = [(0.0, 0.0), (l3b, 0.0), point_c]
    area = 0.5 * abs(l3b * point_c[1])
    plate_mass = density * plate_thickness * area
    sides = [math.dist(corners[i], corners[(i + 1) % 3]) for i in range(3)]
    plate_inertia = plate_mass * sum(s**2 for s in sides) / 36.0
    centroid = [sum(p[0] for p in corners) / 3.0, sum(p[1] for p in corners) / 3.0]

    a = (o1[0] + l1, o1[1])
    b = _upper_intersection(a, l2, o2, l3b)
    plate_angle = math.atan2(b[1] - o2[1], b[0] - o2[0])
    c = (o2[0] + l3c * math.cos(plate_angle + c_angle), o2[1] + l3c * math.sin(plate_angle + c_angle))
    d = _upper_intersection(c, l4, o3, l5)
    material = {"density": density, "youngs_modulus": youngs_modulus}
    bar = {"type": "rigid", "width": width, "thickness": 0.006, "density": density}
    parts = {"type": "fem", "n_elements": n_elements}
    elastic = dict(width=width, thickness=thickness, material=material, discretisation=parts,
                   damping_ratio=damping_ratio, geometric_stiffening=geometric_stiffening)

    def pin(link_a: str, point_a: Any, link_b: str, point_b: Any) -> dict[str, Any]:
        return {"type": "revolute", "link_a": link_a, "point_a": point_a, "link_b": link_b,
                "point_b": point_b}

    spec = {
        "name": name,
        "initial_angles": {"crank": 0.0, "link2": _angle(a, b), "plate": _angle(o2, b),
                           "link4": _angle(c, d), "output": _angle(o3, d)},
        "links": {
            "crank": {**bar, "length": l1},
            "link2": _elastic(l2, **elastic),
            "plate": {"type": "rigid", "length": l3b, "mass": plate_mass,
                      "inertia": plate_inertia, "centroid": centroid,
                      "points": {"C": list(point_c)}},
            "link4": _elastic(l4, **elastic),
            "output": {**bar, "length": l5},
        },
        "joints": {
            "O1": pin("ground", list(o1), "crank", "start"),
            "A": pin("crank", "end", "link2", "start"),
            "B": pin("link2", "end", "plate", "end"),
            "O2": pin("ground", list(o2), "plate", "start"),
            "C": pin("plate", "C", "link4", "start"),
            "D": pin("link4", "end", "output", "end"),
            "O3": pin("ground", list(o3), "output", "start"),
        },
        "drive": {"type": "prescribed", "joint": "O1", "rate": crank_speed},
    }
    return build(spec, source="six_bar()")


def slider_crank(*, crank_speed: float = 150.0, crank: float = 0.15, rod: float = 0.30,
                 rod_width: float = 0.025, rod_thickness: float = 0.008,
                 slider_mass: float = 0.5, n_elements: int = 4, damping_ratio: float = 0.02,
                 geometric_stiffening: bool = True, name: str = "slider_crank") -> Mechanism:
    """An in-line slider-crank: rigid steel crank OA (30 x 10 mm), elastic steel connecting rod AB
    (``rod_width x rod_thickness``, bending in the plane about the thin direction), slider block B
    of ``slider_mass`` kg on the x-axis. The rod's first pinned-pinned bending frequency
    (1283 rad/s for the defaults) is 8.6 times the crank speed, and the slider's peak inertia force
    m r w^2 (1 + r/l) = 2.5 kN is about a tenth of the rod's Euler load (23 kN): the rod vibrates
    visibly and geometric stiffening matters, but the rod does not buckle.
    """
    spec = {
        "name": name,
        "initial_angles": {"crank": 0.0, "rod": 0.0},
        "links": {
            "crank": {"type": "rigid", "length": crank, "width": 0.030, "thickness": 0.010,
                      "density": STEEL["density"]},
            "rod": _elastic(rod, width=rod_width, thickness=rod_thickness, material=STEEL,
                            discretisation={"type": "fem", "n_elements": n_elements},
                            damping_ratio=damping_ratio,
                            geometric_stiffening=geometric_stiffening),
        },
        "joints": {
            "O": {"type": "revolute", "link_a": "ground", "point_a": [0.0, 0.0],
                  "link_b": "crank", "point_b": "start"},
            "A": {"type": "revolute", "link_a": "crank", "point_a": "end", "link_b": "rod",
                  "point_b": "start"},
            "B": {"type": "slider", "link": "rod", "point": "end", "origin": [0.0, 0.0],
                  "angle": 0.0},
        },
        "drive": {"type": "prescribed", "joint": "O", "rate": crank_speed},
        "point_masses": {"slider": {"link": "rod", "point": "end", "mass": slider_mass}},
    }
    return build(spec, source="slider_crank()")


def two_link_arm(*, period: float = 1.0, shoulder_amplitude: float = 0.3,
                 elbow_offset: float = 1.0, elbow_amplitude: float = 0.25,
                 upper_length: float = 0.4, forearm_length: float = 0.3, width: float = 0.025,
                 thickness: float = 0.005, payload: float = 0.2, n_elements: int = 2,
                 damping_ratio: float = 0.02, gravity: tuple[float, float] = (0.0, 0.0),
                 name: str = "two_link_arm") -> Mechanism:
    """A two-link arm (seed Fig. 1.3) moving in a horizontal plane: elastic aluminium links
    clamped at their joints (clamped-free floating frames), a ``payload`` (kg) at the tip, joints
    driven by prescribed periodic motions (rad, period in s):

        shoulder(t) = shoulder_amplitude sin(2 pi t / period)
        elbow(t)    = elbow_offset + elbow_amplitude sin(2 pi t / period)
    """
    elastic = dict(width=width, thickness=thickness, material=ALUMINIUM,
                   discretisation={"type": "fem", "n_elements": n_elements},
                   damping_ratio=damping_ratio, geometric_stiffening=True,
                   boundary="clamped-free")
    spec = {
        "name": name,
        "period": period,
        "gravity": list(gravity),
        "initial_angles": {"upper": 0.0, "forearm": elbow_offset},
        "links": {"upper": _elastic(upper_length, **elastic),
                  "forearm": _elastic(forearm_length, **elastic)},
        "joints": {
            "shoulder": {"type": "revolute", "link_a": "ground", "point_a": [0.0, 0.0],
                         "link_b": "upper", "point_b": "start"},
            "elbow": {"type": "revolute", "link_a": "upper", "point_a": "end",
                      "link_b": "forearm", "point_b": "start"},
        },
        "drives": {
            "shoulder": {"type": "prescribed", "harmonics": [[1, 0.0, shoulder_amplitude]]},
            "elbow": {"type": "prescribed", "offset": elbow_offset,
                      "harmonics": [[1, 0.0, elbow_amplitude]]},
        },
        "point_masses": {"payload": {"link": "forearm", "point": "end", "mass": payload}},
    }
    return build(spec, source="two_link_arm()")
