"""What a steady state keeps to draw the mechanism: link outlines without deflection (to redraw at
another magnification), rigid plates, joint positions and the drive that sets the abscissa.

Everything here is taken from the rigid nominal motion (``lin.nominal.s``, the frame coordinates
``<link>.x``, ``<link>.y``, ``<link>.theta`` of each link over the period), so it does not depend on
the magnification of the elastic deflection; ``MechanismProblem.outlines`` adds that deflection.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np


def _poses(context: Any, link_name: str) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(x, y, theta)`` each (N+1,) of a link's frame over the period, m and rad."""
    labels = list(context.nominal.model.coord_labels)
    s = context.nominal.s
    return tuple(s[:, labels.index(f"{link_name}.{c}")] for c in ("x", "y", "theta"))


def _place(context: Any, link: Any, local: np.ndarray) -> np.ndarray:
    """Points ``local`` (k, 2) m in a link's frame placed over the period: (N+1, k, 2) m."""
    x, y, theta = _poses(context, link.name)
    c, s = np.cos(theta)[:, None], np.sin(theta)[:, None]
    return np.stack([x[:, None] + c * local[:, 0] - s * local[:, 1],
                     y[:, None] + s * local[:, 0] + c * local[:, 1]], axis=-1)


def plate_corners(link: Any) -> np.ndarray:
    """The corners (k, 2) m in the link frame of a rigid link with named points (a plate): the convex
    hull of its pins and its points, counter-clockwise (a point inside, such as a platform's centre,
    or one on an edge, is no corner)."""
    points = sorted({(0.0, 0.0), (float(link.length), 0.0)}
                    | {tuple(map(float, p)) for p in link.points.values()})

    def turn(o, a, b):
        return (a[0] - o[0]) * (b[1] - o[1]) - (a[1] - o[1]) * (b[0] - o[0])

    # Andrew's monotone chain: the lower and the upper hull, each without its last point
    hull: list = []
    for sweep in (points, points[::-1]):
        chain: list = []
        for point in sweep:
            while len(chain) >= 2 and turn(chain[-2], chain[-1], point) <= 0:
                chain.pop()
            chain.append(point)
        hull += chain[:-1]
    return np.array(hull if len(hull) >= 3 else points)


def mechanism_drawing(context: Any, *, n_points: int = 21) -> dict[str, Any]:
    """The drawing fields of a mechanism's steady state (``SteadyStateResult``): ``rigid_outlines``
    {link: (N+1, n_points, 2)} m, points along each link's axis without deflection (the same points
    as ``outlines``); ``plates`` {link: (N+1, k, 2)} m the corners of each rigid link that has
    named points; ``joints`` {joint: (N+1, 2)} m where each joint is (on its first link, nominal);
    ``ground_joints`` the names of the joints on the ground; ``drive`` the joint of the first
    turning drive ("" when no drive turns: the response is then drawn against time) and
    ``drive_rate`` its rate, rad/s."""
    mechanism = context.mechanism
    links = {link.name: link for link in mechanism.links}
    rigid_outlines, plates, joints, ground = {}, {}, {}, []
    for link in mechanism.links:
        xi = np.linspace(0.0, float(link.length), n_points)
        rigid_outlines[link.name] = _place(context, link, np.stack([xi, np.zeros_like(xi)], axis=1))
        if getattr(link, "points", None):
            plates[link.name] = _place(context, link, plate_corners(link))
    for joint in mechanism.joints:
        link_name, point = joint.ends[0]
        link = links[link_name]
        joints[joint.name] = _place(context, link, np.array([link.point_position(point)]))[:, 0]
        if len(joint.ends) == 1:  # the other side is the ground (a ground pin or a slider's line)
            ground.append(joint.name)
    turning = [drive for drive in mechanism.drives if getattr(drive, "rate", 0.0)]
    drive = turning[0] if turning else None
    return {"rigid_outlines": rigid_outlines, "plates": plates, "joints": joints,
            "ground_joints": tuple(ground), "drive": drive.joint if drive else "",
            "drive_rate": float(drive.rate) if drive else math.nan}


def magnified(rigid: np.ndarray, drawn: np.ndarray, stored: float, wanted: float) -> np.ndarray:
    """Points drawn with the deflection magnified ``stored`` times, redrawn ``wanted`` times: the
    deflection ``drawn - rigid`` is linear in the magnification."""
    return rigid + (wanted / stored) * (drawn - rigid)


#: Link colours cycle through matplotlib's default colours; ground pins are drawn as triangles.
GROUND_STYLE = {"marker": "^", "color": "k", "ms": 9, "mfc": "0.8", "ls": "none", "zorder": 4}
JOINT_STYLE = {"marker": "o", "color": "k", "ms": 5, "mfc": "w", "ls": "none", "zorder": 5}


def frame_points(result: Any, k: int, magnification: float | None = None
                 ) -> tuple[dict[str, np.ndarray], dict[str, np.ndarray], dict[str, np.ndarray]]:
    """``(outlines, plates, joints)`` of a steady state at sample ``k``: {link: (n_points, 2)},
    {link: (n_corners, 2)}, {joint: (2,)} m, the deflection magnified ``magnification`` times
    (default: the result's own; another one needs ``rigid_outlines``, which older files lack)."""
    outlines = {name: points[k] for name, points in result.outlines.items()}
    if magnification is not None and magnification != result.magnification:
        outlines = {name: magnified(result.rigid_outlines[name][k], points, result.magnification,
                                    magnification) for name, points in outlines.items()}
    plates = {name: corners[k] for name, corners in (result.plates or {}).items()}
    joints = {name: position[k] for name, position in (result.joints or {}).items()}
    return outlines, plates, joints


def draw_mechanism(ax: Any, result: Any, k: int, *, magnification: float | None = None,
                   alpha: float = 1.0, legend: bool = True) -> dict[str, list]:
    """Draw the mechanism of a steady state at sample ``k`` into ``ax``: each link's outline (a
    polyline, its deflection magnified), plates (filled polygons), joints (circles) and ground pins
    (triangles). Returns the artists {link or joint name: [Artist, ...]}."""
    outlines, plates, joints = frame_points(result, k, magnification)
    artists: dict[str, list] = {}
    for j, (name, points) in enumerate(outlines.items()):
        colour = f"C{j % 10}"
        if name in plates:
            artists[name] = [ax.fill(plates[name][:, 0], plates[name][:, 1], color=colour, alpha=0.35 * alpha,
                                     ec=colour, lw=1.5, label=name if legend else None)[0]]
        else:
            artists[name] = ax.plot(points[:, 0], points[:, 1], color=colour, alpha=alpha, lw=2.0,
                                    label=name if legend else None)
    ground = set(result.ground_joints or ())
    for name, position in joints.items():
        style = GROUND_STYLE if name in ground else JOINT_STYLE
        artists[f"joint {name}"] = ax.plot(position[0], position[1], alpha=alpha, **style)
    return artists


def draw_names(ax: Any, drawing: dict[str, Any], k: int = 0) -> dict[str, list]:
    """Draw the rigid mechanism of ``drawing`` (``mechanism_drawing``) at sample ``k`` with the name
    of each link (at its middle) and joint (beside it), for ``flexvib show --out``; equal axes in m.
    Returns the artists {name: [Artist, ...]}."""
    artists: dict[str, list] = {}
    plates = drawing["plates"]
    ground = set(drawing["ground_joints"])
    for j, (name, points) in enumerate(drawing["rigid_outlines"].items()):
        colour = f"C{j % 10}"
        if name in plates:
            corners = plates[name][k]
            artists[name] = [ax.fill(corners[:, 0], corners[:, 1], color=colour, alpha=0.35, ec=colour, lw=1.5)[0]]
            middle = corners.mean(axis=0)
        else:
            line = points[k]
            artists[name] = ax.plot(line[:, 0], line[:, 1], color=colour, lw=2.5)
            middle = line[len(line) // 2]
        artists[name].append(ax.annotate(name, middle, xytext=(0, 6), textcoords="offset points", ha="center",
                                         va="bottom", fontsize="small", color=colour, fontweight="bold"))
    for name, position in drawing["joints"].items():
        style = GROUND_STYLE if name in ground else JOINT_STYLE
        artists[f"joint {name}"] = ax.plot(position[k][0], position[k][1], **style)
        artists[f"joint {name}"].append(ax.annotate(name, position[k], xytext=(5, -11), textcoords="offset points",
                                                    fontsize="small"))
    ax.set_aspect("equal", adjustable="datalim")
    ax.margins(0.12)
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    return artists
