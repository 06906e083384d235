"""jaxlink: planar mechanisms in JAX — a vectorized, differentiable Newton loop-closure solver,
kinematics, reactions, design search and cam-follower dynamics.

The library follows the dtype of its inputs; call
`jax.config.update("jax_enable_x64", True)` for float64 (the command line does).
"""

from ._assemble import NewtonOptions as NewtonOptions
from ._assemble import solve as solve
from ._assemble import solve_path as solve_path
from ._errors import MechanismError as MechanismError
from ._kinematics import Transfer as Transfer
from ._kinematics import time_derivatives as time_derivatives
from ._kinematics import transfer as transfer
from ._mechanism import Mechanism as Mechanism
from ._mechanism import load as load
from ._mechanism import loads as loads
from ._solution import RESULTS as RESULTS
from ._solution import Solution as Solution

__version__ = "0.1.0"
