"""Planar mechanisms with elastic links in redundant generalized coordinates."""

from ._parts import (GROUND as GROUND, DampingMatrix as DampingMatrix, ElasticLink as ElasticLink,
                     Fem as Fem, Mechanism as Mechanism, ModalDamping as ModalDamping,
                     PointMass as PointMass, PrescribedDrive as PrescribedDrive,
                     Rayleigh as Rayleigh, Revolute as Revolute, RigidLink as RigidLink, Ritz as Ritz,
                     Slider as Slider, TorqueDrive as TorqueDrive, UserShapes as UserShapes)
from ._assemble import (LinkLayout as LinkLayout, Model as Model, assemble as assemble,
                        drive_law as drive_law)
from ._beams import (BeamShapes as BeamShapes, beam_matrices as beam_matrices,
                     beam_shapes as beam_shapes)
from ._protocol import ConstrainedModel as ConstrainedModel, Observable as Observable
from ._simulate import (SimulationError as SimulationError, SimulationResult as SimulationResult,
                        simulate as simulate)
