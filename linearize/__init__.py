"""Linearisation of a mechanism's constrained equations about its nominal rigid motion."""

from ._core import (LinearCoefficients as LinearCoefficients,
                    LinearizationError as LinearizationError,
                    linear_coefficients as linear_coefficients,
                    spectral_derivatives as spectral_derivatives)
