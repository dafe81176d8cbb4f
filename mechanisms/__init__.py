"""Planar mechanisms with elastic links in redundant generalized coordinates."""

from ._parts import (GROUND as GROUND, DampingMatrix as DampingMatrix, ElasticLink as ElasticLink,
                     Fem as Fem, Mechanism as Mechanism, ModalDamping as ModalDamping,
                     PointMass as PointMass, PrescribedDrive as PrescribedDrive,
                     Rayleigh as Rayleigh, Revolute as Revolute, RigidLink as RigidLink, Ritz as Ritz,
                     Slider as Slider, TorqueDrive as TorqueDrive, UserShapes as UserShapes)
from ._simulate import (SimulationError as SimulationError, SimulationResult as SimulationResult,
                        simulate as simulate)
