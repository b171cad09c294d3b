"""pwas-hdl: piecewise-affine simplicial (PWAS) virtual sensors, from plant data to verified Verilog."""

from pwas_hdl.fit.geometry import Grid, Location
from pwas_hdl.fit.regressors import LagStructure
from pwas_hdl.fit.regularized_lsq import CVResult, cross_validate_sigma, solve_regularized, tikhonov_matrix
from pwas_hdl.fit.virtual_sensor import PWASVirtualSensor, load_model

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
