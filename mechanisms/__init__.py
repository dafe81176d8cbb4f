"""Planar mechanisms with elastic links in redundant generalized coordinates."""

from ._parts import (GROUND as GROUND, DampingMatrix as DampingMatrix, ElasticLink as ElasticLink,
                     CONTROLLER_TYPES as CONTROLLER_TYPES, DCMotor as DCMotor,
                     ObservableFeedback as ObservableFeedback, PDController as PDController,
                     Fem as Fem, Mechanism as Mechanism, ModalDamping as ModalDamping,
                     PointMass as PointMass, PrescribedDrive as PrescribedDrive,
                     Rayleigh as Rayleigh, Revolute as Revolute, RigidLink as RigidLink, Ritz as Ritz,
                     Slider as Slider, TorqueDrive as TorqueDrive, UserShapes as UserShapes)
from ._assemble import (JointRows as JointRows, LinkLayout as LinkLayout, Model as Model,
                        assemble as assemble, drive_law as drive_law)
from ._batch import (ConstraintTerms as ConstraintTerms, LinearTerms as LinearTerms,
                     constraint_terms_along as constraint_terms_along,
                     inertia_residual_along as inertia_residual_along,
                     linear_terms_along as linear_terms_along)
from ._beams import (BeamShapes as BeamShapes, beam_matrices as beam_matrices,
                     beam_shapes as beam_shapes)
from ._parts import ArgumentError as ArgumentError, MechanismError as MechanismError
from ._parts import DISCRETISATION_TYPES as DISCRETISATION_TYPES, JOINT_TYPES as JOINT_TYPES
from ._load import build as build, load as load, loads as loads, scenes as scenes
from ._scenes import (four_bar as four_bar, six_bar as six_bar, slider_crank as slider_crank,
                      two_link_arm as two_link_arm, parallel_robot as parallel_robot)
from ._kinematics import (ConvergenceError as ConvergenceError, NominalMotion as NominalMotion,
                          feedforward_torques as feedforward_torques,
                          nominal_motion as nominal_motion)
from ._observables import default_observables as default_observables
from ._protocol import ConstrainedModel as ConstrainedModel, Observable as Observable
from ._simulate import (SimulationError as SimulationError, SimulationResult as SimulationResult,
                        integrated_model as integrated_model, simulate as simulate)
from ._orbit import PeriodMap as PeriodMap, PeriodRun as PeriodRun
