"""Builders for the shipped scenes, in Python, with keyword-only parameters.

Each builder writes a scene spec (the same tables as the TOML files in ``mechanisms/scenes/``,
documented in ``docs/scenes.md``) and builds it, so the result keeps its spec and
``with_parameter`` works on it exactly as on a loaded scene. With default arguments each builder
equals its shipped scene (tested).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

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
    """The thesis four-bar OABC (thesis Fig. 2.5): rigid uniform crank OA and rocker CB, elastic
    coupler AB, all of section ``width x thickness`` (m) bending about the thin direction.

    Lengths in m, ``crank_speed`` in rad/s (crank angle ``crank_speed * t`` from the x-axis),
    ``damping_ratio`` of stiffness-proportional damping at the coupler's first pinned-pinned bending
    frequency (beta = 2 zeta / omega_1). ``geometric_stiffening=False`` with ``discretisation="ritz"``
    is the thesis's energy expressions exactly (scene ``four_bar_thesis``).
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
    """The Watt II six-bar of the thesis's Fig. 1.2: crank 1 (O1A), elastic link 2 (AB), rigid plate 3
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
    """A two-link arm (thesis Fig. 1.3) moving in a horizontal plane: elastic aluminium links
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


def _three_rrr_inverse_kinematics(centre: np.ndarray, *, base: np.ndarray, platform: np.ndarray,
                                  proximal: float, distal: float) -> np.ndarray:
    """Base angles (rad, from the x-axis) of a 3-RRR robot whose platform centre is at ``centre``
    (n, 2) m with its joints at ``centre + platform[i]`` (constant orientation); ``base`` (3, 2) m
    the base joints, ``platform`` (3, 2) m the platform joints from the centre. Elbows on the right
    of each line base -> platform joint (clockwise from it). Returns (n, 3), unwrapped in time."""
    to_joint = centre[:, None, :] + platform[None, :, :] - base[None, :, :]          # (n, 3, 2)
    reach = np.hypot(to_joint[..., 0], to_joint[..., 1])
    cos_inner = (proximal**2 + reach**2 - distal**2) / (2.0 * proximal * reach)
    if np.any(np.abs(cos_inner) >= 1.0):
        raise MechanismError(f"parallel_robot: legs of {proximal:.6g} m and {distal:.6g} m cannot "
                             f"reach the platform joints at distances {reach.min():.6g} to "
                             f"{reach.max():.6g} m from the base joints")
    return np.unwrap(np.arctan2(to_joint[..., 1], to_joint[..., 0]) - np.arccos(cos_inner), axis=0)


def _drive_harmonics(angles: np.ndarray, tolerance: float) -> tuple[float, list[list[float]]]:
    """Fourier series of one period of ``angles`` (n,) rad sampled at ``t_j = j T / n``: the mean
    and ``[k, cos_k, sin_k]`` for each ``k`` up to the last one with a coefficient above
    ``tolerance`` (rad), coefficients rounded to 1e-13 rad so that the scene file's decimals
    rebuild them exactly."""
    n = angles.size
    coefficients = np.fft.rfft(angles) / n
    cos_k, sin_k = 2.0 * coefficients.real, -2.0 * coefficients.imag
    significant = np.flatnonzero(np.hypot(cos_k, sin_k)[1:n // 2] > tolerance) + 1
    if significant.size and significant[-1] >= n // 4:
        raise MechanismError("parallel_robot: the drive angles' Fourier series does not converge "
                             "on the sampled period (the path passes too near a singularity)")
    last = int(significant[-1]) if significant.size else 0
    return (round(float(coefficients[0].real), 13),
            [[k, round(float(cos_k[k]), 13), round(float(sin_k[k]), 13)] for k in range(1, last + 1)])


def parallel_robot(*, period: float = 0.2, base_radius: float = 0.25,
                   platform_radius: float = 0.06, proximal: float = 0.15, distal: float = 0.15,
                   path_radius: float = 0.03, proximal_width: float = 0.03,
                   proximal_thickness: float = 0.005, payload: float = 0.5, n_elements: int = 2,
                   damping_ratio: float = 0.02, gravity: tuple[float, float] = (0.0, 0.0),
                   name: str = "parallel_robot") -> Mechanism:
    """A 3-RRR planar parallel robot (thesis Fig. 1.5) in a horizontal plane: three base joints O1, O2,
    O3 at the corners of an equilateral triangle of circumradius ``base_radius`` (at 90, 210 and 330
    deg), each driving an elastic proximal link (clamped to its motor, aluminium
    ``proximal_width x proximal_thickness``, the thickness in the plane), pinned at the elbow to a
    rigid distal bar, pinned to a rigid triangular platform (joints at ``platform_radius`` from its
    centre, same directions as the base corners) carrying a ``payload`` (kg) at its centre.

    The drives' periodic laws (``period`` s) are the closed-form inverse kinematics of the platform
    centre going round a circle of ``path_radius`` m about the base centre, counter-clockwise,
    starting on the +x side, with constant orientation, as Fourier series truncated at 1e-12 rad.
    """
    corners = np.radians([90.0, 210.0, 330.0])
    directions = np.column_stack([np.cos(corners), np.sin(corners)])
    base, platform_joints = base_radius * directions, platform_radius * directions
    samples = 512
    phase = 2.0 * math.pi * np.arange(samples) / samples
    centre = path_radius * np.column_stack([np.cos(phase), np.sin(phase)])
    angles = _three_rrr_inverse_kinematics(centre, base=base, platform=platform_joints,
                                           proximal=proximal, distal=distal)
    legs = range(1, 4)
    drives = {}
    for leg in legs:
        offset, harmonics = _drive_harmonics(angles[:, leg - 1], 1e-12)
        drives[f"O{leg}"] = {"type": "prescribed", "offset": offset, "harmonics": harmonics}
    # The assembly at t = 0: elbows from the base angles, distal angles towards the platform joints.
    elbows = base + proximal * np.column_stack([np.cos(angles[0]), np.sin(angles[0])])
    ends = centre[0] + platform_joints
    initial = {f"proximal{leg}": _angle(tuple(base[leg - 1]), tuple(elbows[leg - 1]))
               for leg in legs}
    initial.update({f"distal{leg}": _angle(tuple(elbows[leg - 1]), tuple(ends[leg - 1]))
                    for leg in legs})
    # Platform frame: origin at its centre (start), x-axis towards its joint A1 (end, at 90 deg).
    initial["platform"] = round(float(corners[0]), 4)
    relative = corners - corners[0]
    points = {f"A{leg}": [round(platform_radius * math.cos(relative[leg - 1]), 15),
                          round(platform_radius * math.sin(relative[leg - 1]), 15)] for leg in legs}
    points["centre"] = [0.0, 0.0]
    # Aluminium triangular plate 10 mm thick: area (3 sqrt(3) / 4) R^2, polar moment m a^2 / 12
    # about its centroid for the side a = sqrt(3) R.
    plate_mass = ALUMINIUM["density"] * 0.010 * 3.0 * math.sqrt(3.0) / 4.0 * platform_radius**2
    plate_inertia = plate_mass * 3.0 * platform_radius**2 / 12.0
    links: dict[str, Any] = {}
    for leg in legs:
        links[f"proximal{leg}"] = _elastic(
            proximal, width=proximal_width, thickness=proximal_thickness, material=ALUMINIUM,
            discretisation={"type": "fem", "n_elements": n_elements},
            damping_ratio=damping_ratio, geometric_stiffening=True, boundary="clamped-free")
    for leg in legs:
        links[f"distal{leg}"] = {"type": "rigid", "length": distal, "width": 0.02,
                                 "thickness": 0.01, "density": ALUMINIUM["density"]}
    links["platform"] = {"type": "rigid", "length": platform_radius, "mass": plate_mass,
                         "inertia": plate_inertia, "centroid": [0.0, 0.0], "points": points}
    joints: dict[str, Any] = {}
    for leg in legs:
        joints[f"O{leg}"] = {"type": "revolute", "link_a": "ground",
                             "point_a": [round(float(c), 15) for c in base[leg - 1]],
                             "link_b": f"proximal{leg}", "point_b": "start"}
        joints[f"E{leg}"] = {"type": "revolute", "link_a": f"proximal{leg}", "point_a": "end",
                             "link_b": f"distal{leg}", "point_b": "start"}
        joints[f"P{leg}"] = {"type": "revolute", "link_a": f"distal{leg}", "point_a": "end",
                             "link_b": "platform", "point_b": f"A{leg}"}
    spec = {
        "name": name,
        "period": period,
        "gravity": list(gravity),
        "initial_angles": initial,
        "links": links,
        "joints": joints,
        "drives": drives,
        "point_masses": {"payload": {"link": "platform", "point": "centre", "mass": payload}},
    }
    return build(spec, source="parallel_robot()")
