"""The parts a planar mechanism is made of: links, joints, point masses, drives, controllers.

Conventions shared by every module of ``mechanisms`` (and relied on by ``linearize``):

* SI units and radians everywhere.
* Every link carries a *floating frame* whose origin is the link's first pin ("start") and whose
  x-axis points to its second pin ("end"). For a rigid link that frame is fixed in the body. For an
  elastic link with ``boundary="pinned-pinned"`` the frame is the chord frame: the transverse
  deflection ``w`` is zero at both pins and the axial displacement ``u`` is zero at the start, so the
  end pin sits at local ``(length + u(length), 0)``. With ``boundary="clamped-free"`` (robot arms) the
  frame is tangent at the start: ``w(0) = w'(0) = u(0) = 0`` and the tip is free.
* Generalized coordinates are redundant: for each link, in the order the links are given,
  ``(x, y, theta)`` of its frame origin and angle, followed by its elastic coordinates.
* A point on a link is named by a string: ``"start"``, ``"end"``, a key of ``RigidLink.points``, or
  a float in ``[0, length]`` (a position along the undeformed x-axis of the link). A point on the ground
  is a pair of floats ``(x, y)`` in metres.

Every part checks its own numbers when it is made, and a ``Mechanism`` checks how the parts fit
together (names, mobility, Grashof for four-bars), raising ``MechanismError`` (a ``ValueError``) that
names the offending part and key. Checks that need the assembled equations (assembly at ``t = 0``, a
crank that cannot turn, toggle positions) run at the start of ``mechanisms.nominal_motion``.

One module per noun: ``checks`` (errors, shared checks, limits), ``discretisations`` (their
registry and interface; ``fem`` and ``ritz`` hold the built-in ones with their shapes),
``damping``, ``links``, ``rows`` (the constraint-row vocabulary), ``joints``, ``drives``,
``controllers``, ``mechanism`` (with ``grashof``); the scene spec is read by ``table`` and
``scene`` and written by ``spec``.
"""

from .checks import GROUND as GROUND
from .checks import ArgumentError as ArgumentError
from .checks import MechanismError as MechanismError
from .controllers import CONTROLLER_TYPES as CONTROLLER_TYPES
from .controllers import ControllerLaw as ControllerLaw
from .controllers import ObservableFeedback as ObservableFeedback
from .controllers import PDController as PDController
from .controllers import register_controller as register_controller
from .damping import DAMPING_TYPES as DAMPING_TYPES
from .damping import DampingMatrix as DampingMatrix
from .damping import ModalDamping as ModalDamping
from .damping import Rayleigh as Rayleigh
from .discretisations import DISCRETISATION_TYPES as DISCRETISATION_TYPES
from .discretisations import ShapeLayout as ShapeLayout
from .discretisations import ShapeValues as ShapeValues
from .discretisations import register_discretisation as register_discretisation
from .drives import DRIVE_TYPES as DRIVE_TYPES
from .drives import RAMP_SHAPES as RAMP_SHAPES
from .drives import DCMotor as DCMotor
from .drives import PrescribedDrive as PrescribedDrive
from .drives import RampShape as RampShape
from .drives import SpeedRamp as SpeedRamp
from .drives import TorqueDrive as TorqueDrive
from .drives import drive_law as drive_law
from .drives import register_drive as register_drive
from .drives import register_ramp_shape as register_ramp_shape
from .fem import Fem as Fem
from .joints import JOINT_TYPES as JOINT_TYPES
from .joints import Revolute as Revolute
from .joints import Slider as Slider
from .joints import Slot as Slot
from .joints import register_joint as register_joint
from .links import ElasticLink as ElasticLink
from .links import PointMass as PointMass
from .links import RigidLink as RigidLink
from .mechanism import Mechanism as Mechanism
from .ritz import Ritz as Ritz
from .ritz import UserShapes as UserShapes
from .rows import AngleRow as AngleRow
from .rows import AngleTerm as AngleTerm
from .rows import PointRow as PointRow
from .rows import PointTerm as PointTerm
