"""jaxlink: planar mechanisms in JAX — a vectorized, differentiable Newton loop-closure solver,
kinematics, reactions, design search and cam-follower dynamics.

The library follows the dtype of its inputs; call
`jax.config.update("jax_enable_x64", True)` for float64 (the command line does).
"""

from .solvers.assemble import NewtonOptions as NewtonOptions
from .solvers.assemble import solve as solve
from .solvers.assemble import solve_path as solve_path
from .errors import MechanismError as MechanismError
from .analysis.transfer import Transfer as Transfer
from .analysis.transfer import time_derivatives as time_derivatives
from .analysis.transfer import transfer as transfer
from .model.mechanism import Mechanism as Mechanism
from .files.reader import load as load
from .files.reader import loads as loads
from .results import RESULTS as RESULTS
from .results import Solution as Solution

__version__ = "0.1.0"
