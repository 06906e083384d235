"""jaxlink: planar mechanisms in JAX — a vectorized, differentiable loop-closure solver,
kinematics, reactions, design search and cam-follower dynamics.

The public API (everything else is internal and may change):

- files: `load`, `loads`, `Mechanism`, `MechanismError`; a mechanism from joints and links: `Sketch`;
- positions: `solve`, `solve_path`, `NewtonOptions`, `Solution`, `SolveStats`, `RESULTS`;
- branch points between samples (change points, toggles): `branch_points`, `BranchPoints`;
- the whole closed curve of a linkage whose input cannot turn fully: `whole_curve`, `WholeCurve`;
- the designer's numbers: `four_bars`, `FourBar` (Grashof), `motion`, `Motion` (range of motion,
  transmission angles, strokes, dead centres, time ratio, velocity ratio);
- kinematics: `transfer`, `Transfer`, `time_derivatives`;
- kinetostatics: `reactions`, `solve_reactions`, `Reactions`, `body_motion`, `BodyMotion`;
- dwell (a slider that stands still): `dwell_metrics`, `solve_stroke`, `dwell_roles`, `StrokeScale`, `DwellRoles`;
- path synthesis (topology and dimensions for a target path): `synthesize`;
- subpackages: `jaxlink.optimize` (design search), `jaxlink.cam` (cam-follower dynamics),
  `jaxlink.synthesis` (the distance, targets, topologies).

Every function takes `(mech, phis, …, p)` in that order. The library follows the dtype of its
inputs: call `jax.config.update("jax_enable_x64", True)` for float64 (the command line does).
"""

from .analysis.dwell import DwellRoles as DwellRoles
from .analysis.dwell import StrokeScale as StrokeScale
from .analysis.dwell import dwell_metrics as dwell_metrics
from .analysis.dwell import dwell_roles as dwell_roles
from .analysis.dwell import solve_stroke as solve_stroke
from .analysis.grashof import FourBar as FourBar
from .analysis.grashof import four_bars as four_bars
from .analysis.kinetostatics import BodyMotion as BodyMotion
from .analysis.kinetostatics import Reactions as Reactions
from .analysis.kinetostatics import body_motion as body_motion
from .analysis.kinetostatics import reactions as reactions
from .analysis.kinetostatics import solve_reactions as solve_reactions
from .analysis.motion import Motion as Motion
from .analysis.motion import motion as motion
from .analysis.transfer import Transfer as Transfer
from .analysis.transfer import time_derivatives as time_derivatives
from .analysis.transfer import transfer as transfer
from .analysis.whole_curve import WholeCurve as WholeCurve
from .analysis.whole_curve import whole_curve as whole_curve
from .cache import enable_compilation_cache as enable_compilation_cache
from .errors import MechanismError as MechanismError
from .files.reader import load as load
from .files.reader import loads as loads
from .model.mechanism import Mechanism as Mechanism
from .model.sketch import Sketch as Sketch
from .results import RESULTS as RESULTS
from .results import Solution as Solution
from .results import SolveStats as SolveStats
from .solvers.assemble import solve as solve
from .solvers.assemble import solve_path as solve_path
from .solvers.branch_points import BranchPoints as BranchPoints
from .solvers.branch_points import branch_points as branch_points
from .solvers.options import NewtonOptions as NewtonOptions

if __import__("typing").TYPE_CHECKING:
    from .synthesis.api import synthesize as synthesize

__version__ = "0.1.0"


def __getattr__(name: str):
    """`synthesize` is imported when first used (PEP 562): the path synthesis's modules are 0.03 s
    of every command's start-up (0.1 s where Python writes no bytecode files)."""
    if name == "synthesize":
        from .synthesis.api import synthesize

        globals()[name] = synthesize
        return synthesize
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def __dir__():
    return sorted(set(globals()) | {"synthesize"})
