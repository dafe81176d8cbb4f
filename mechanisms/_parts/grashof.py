"""Grashof's check of a driven four-bar: the crank must pass every angle it is driven through."""

from __future__ import annotations

import math

import numpy as np

from .checks import GROUND, MechanismError
from .drives import _drive_angle
from .links import Link, _pin_position


def check_four_bar(mech, links: dict) -> None:
    """Grashof for a driven four-bar: the crank must pass every angle it is driven through.

    With crank pin O, coupler pin A, rocker pivot C and lengths l_coupler, l_rocker, the loop closes
    exactly when |A - C| lies in [|l_coupler - l_rocker|, l_coupler + l_rocker]. Scanning the crank
    angle over one period finds the first angle where it does not (a non-Grashof linkage, or a
    Grashof one whose crank is not the shortest link); touching the bound is a toggle, where the
    constraint Jacobian is singular (a change-point linkage, s + l = p + q).
    """
    pins = _pins(mech)
    if len(mech.links) != 3 or len(pins) != 4 or len(mech.drives) != 1:
        return
    ground_joints = [name for name, sides in pins.items() if sides[0][0] == GROUND]
    drive_joint = mech.drives[0].joint
    if len(ground_joints) != 2 or drive_joint not in ground_joints:
        return
    crank = links[pins[drive_joint][1][0]]
    rocker_joint = next(name for name in ground_joints if name != drive_joint)
    rocker = links[pins[rocker_joint][1][0]]
    if rocker is crank:
        return
    coupler = next(link for link in mech.links if link is not crank and link is not rocker)
    inner = [name for name, sides in pins.items() if sides[0][0] != GROUND]

    def pin(link: Link, joint: str) -> tuple[float, float]:
        point = next(point for owner, point in pins[joint] if owner == link.name)
        return _pin_position(link, point, f"joint {joint!r}")

    def side(link_a: Link, link_b: Link) -> str | None:
        return next((name for name in inner if {owner for owner, _ in pins[name]} == {link_a.name, link_b.name}),
                    None)

    crank_coupler, coupler_rocker = side(crank, coupler), side(coupler, rocker)
    if crank_coupler is None or coupler_rocker is None:
        return
    o, c = pins[drive_joint][0][1], pins[rocker_joint][0][1]
    crank_vec = [b - a for a, b in zip(pin(crank, drive_joint), pin(crank, crank_coupler))]
    l_coupler = math.dist(pin(coupler, crank_coupler), pin(coupler, coupler_rocker))
    l_rocker = math.dist(pin(rocker, rocker_joint), pin(rocker, coupler_rocker))
    l_crank, l_ground = math.hypot(*crank_vec), math.dist(o, c)
    low, high = abs(l_coupler - l_rocker), l_coupler + l_rocker
    scale = max(l_crank, l_ground, l_coupler, l_rocker)
    drive, period = mech.drives[0], mech.period

    def margin(t: float) -> float:
        theta = drive.angle(t, period)[0]
        ax = o[0] + math.cos(theta) * crank_vec[0] - math.sin(theta) * crank_vec[1]
        ay = o[1] + math.sin(theta) * crank_vec[0] + math.cos(theta) * crank_vec[1]
        d = math.hypot(ax - c[0], ay - c[1])
        return min(d - low, high - d) / scale

    # 4096 samples resolve the crank angle to 0.1 deg per turn; bisection then pins the crossing.
    # The scan is vectorised (it runs whenever a four-bar is made, e.g. at every point of a sweep).
    n_samples = 4096 * max(1, round(abs(drive.rate) * period / (2.0 * math.pi)))
    times = np.linspace(0.0, period, n_samples + 1)
    theta = _drive_angle(drive, times, period)[0]
    d = np.hypot(o[0] + np.cos(theta) * crank_vec[0] - np.sin(theta) * crank_vec[1] - c[0],
                 o[1] + np.sin(theta) * crank_vec[0] + np.cos(theta) * crank_vec[1] - c[1])
    margins = np.minimum(d - low, high - d) / scale
    lengths = sorted([l_crank, l_ground, l_coupler, l_rocker])
    grashof = (f"lengths crank {l_crank:.6g}, coupler {l_coupler:.6g}, rocker {l_rocker:.6g}, "
               f"ground {l_ground:.6g} m: s + l = {lengths[0] + lengths[3]:.6g} m, p + q = "
               f"{lengths[1] + lengths[2]:.6g} m")
    if margins[0] <= 0.0:
        raise MechanismError(f"four-bar {mech.name!r} cannot be assembled at crank angle "
                             f"{math.degrees(drive.angle(0.0, period)[0]):.2f} deg (t = 0): the "
                             f"coupler and rocker cannot reach ({grashof})")
    ratio = (math.sqrt(5.0) - 1.0) / 2.0

    def refined_minimum(k: int) -> tuple[float, float]:
        # Golden-section search of the margin's minimum between the samples around k.
        t_low, t_high = times[max(k - 1, 0)], times[min(k + 1, n_samples)]
        for _ in range(80):
            t_1, t_2 = t_high - ratio * (t_high - t_low), t_low + ratio * (t_high - t_low)
            t_low, t_high = (t_low, t_2) if margin(t_1) < margin(t_2) else (t_1, t_high)
        return margin(t_high), t_high

    opened = np.flatnonzero(margins < 0.0)
    if opened.size:
        k_open = int(opened[0])
        # The loop opens: bisect for the first angle where it no longer closes.
        kind = "the coupler and rocker cannot reach beyond it"
        t_low, t_high = times[k_open - 1], times[k_open]
        for _ in range(60):
            t_mid = 0.5 * (t_low + t_high)
            t_low, t_high = (t_mid, t_high) if margin(t_mid) > 0.0 else (t_low, t_mid)
    else:
        # A toggle touches margin 0 without crossing, between samples: refine every local minimum
        # of the samples. 1e-9 of the largest length is far below any physical clearance and far
        # above rounding (1e-16).
        inner_margins = margins[1:-1]
        candidates = np.flatnonzero((inner_margins <= margins[:-2]) & (inner_margins <= margins[2:])
                                    & (inner_margins < 1e-3)) + 1
        minima = [refined_minimum(int(k)) for k in candidates]
        toggles = [t for value, t in minima if value <= 1e-9]
        if not toggles:
            return
        kind = ("toggle: the constraint Jacobian of joints "
                f"{crank_coupler!r}, {coupler_rocker!r} is singular there")
        t_high = toggles[0]
    angle = drive.angle(t_high, period)[0]
    raise MechanismError(
        f"four-bar {mech.name!r}: the crank cannot turn fully; it fails at crank angle "
        f"{math.degrees(angle):.2f} deg (t = {t_high:.6g} s), {kind}. Grashof needs s + l <= p + q "
        f"with the crank the shortest link (or the ground shortest), strictly for no toggle; "
        f"{grashof}")


def _pins(mech) -> dict[str, tuple]:
    """``{joint: ((link, point), (link, point))}`` of the joints that pin two points together (those
    whose ``coincident_points()`` name them: a revolute joint, a registered pin), a ground side first
    (its point a ground position ``(x, y)``)."""
    pins = {}
    for joint in mech.joints:
        sides = tuple(joint.coincident_points())
        if sides:
            pins[joint.name] = sides[::-1] if sides[1][0] == GROUND else sides
    return pins
