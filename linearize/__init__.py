"""Linearisation of a mechanism's constrained equations about its nominal rigid motion."""

from ._about import LinearizedMechanism as LinearizedMechanism
from ._about import SpeedFamily as SpeedFamily
from ._about import about as about
from ._about import default_observables as default_observables
from ._about import speed_family as speed_family
from ._about import supports_speed_family as supports_speed_family
from ._core import LinearCoefficients as LinearCoefficients
from ._core import LinearizationError as LinearizationError
from ._core import linear_coefficients as linear_coefficients
from ._core import spectral_derivatives as spectral_derivatives
from ._geometric import geometric_stiffness as geometric_stiffness
from ._observe import ObservableMap as ObservableMap
from ._range import LINEAR_RANGE_LIMITS as LINEAR_RANGE_LIMITS
from ._range import DriveRange as DriveRange
from ._range import LinearRange as LinearRange
from ._range import LinkRange as LinkRange
from ._reduction import REDUCTION_TOL as REDUCTION_TOL
from ._reduction import ReductionCheck as ReductionCheck
from ._reduction import reduced_links as reduced_links
from ._reduction import reduction_error as reduction_error
from ._reduction import reference_mechanism as reference_mechanism
from ._residual import LinearisationError as LinearisationError
from ._residual import linearisation_error as linearisation_error
from ._residual import nonlinear_residual as nonlinear_residual
