"""Linearisation of a mechanism's constrained equations about its nominal rigid motion."""

from ._core import (LinearCoefficients as LinearCoefficients,
                    LinearizationError as LinearizationError,
                    linear_coefficients as linear_coefficients,
                    spectral_derivatives as spectral_derivatives)
from ._about import (LinearizedMechanism as LinearizedMechanism, SpeedFamily as SpeedFamily,
                     about as about, default_observables as default_observables,
                     speed_family as speed_family)
from ._geometric import geometric_stiffness as geometric_stiffness
from ._observe import ObservableMap as ObservableMap
from ._range import (LINEAR_RANGE_LIMITS as LINEAR_RANGE_LIMITS, LinearRange as LinearRange,
                     DriveRange as DriveRange,
                     LinkRange as LinkRange)
from ._reduction import (REDUCTION_TOL as REDUCTION_TOL, ReductionError as ReductionError,
                         reduced_links as reduced_links, reduction_error as reduction_error,
                         reference_mechanism as reference_mechanism)
