"""pwas-hdl: piecewise-affine simplicial (PWAS) virtual sensors, from plant data to verified Verilog."""

from .geometry import Grid, Location
from .regressors import LagStructure
from .regularized_lsq import CVResult, cross_validate_sigma, solve_regularized, tikhonov_matrix
from .virtual_sensor import PWASVirtualSensor, load_model

__all__ = [
    "Grid",
    "Location",
    "LagStructure",
    "CVResult",
    "cross_validate_sigma",
    "solve_regularized",
    "tikhonov_matrix",
    "PWASVirtualSensor",
    "load_model",
]
__version__ = "0.1.0"
