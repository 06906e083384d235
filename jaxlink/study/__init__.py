"""Parameter studies on the batched, differentiable evaluator (`jaxlink study`).

The tolerance analysis around one design — exact first order (RSS σ, linear worst case,
importance factors) from the Jacobian of the responses over the whole cycle, and Monte Carlo with
the tolerances' distributions, streamed; feasibility over the whole cycle counted — and the
design-space studies over ranges: `sample` (scrambled Sobol', Halton, Latin hypercube, random),
`grid` (full factorial) and `sensitivity` (Sobol' S1/ST with bootstrap intervals of every response
along the cycle and of the feasibility).

- inputs: `read_study`, `StudyInputs`, `Tolerance`, `Range` (the `[study]` table);
- designs: `unit_blocks` (the samplers), `to_values` (unit cube → parameters);
- design-space studies: `sample`, `sensitivity`, `SampleReport`, `SensitivityReport`;
- Sobol' estimators: `sobol_indices`, `SobolIndices`, `SobolAccumulator`;
- responses: `Responses` (points' x, y over the cycle, stroke/swing, max speed/acceleration);
- the analysis: `tolerance`, `Study`, `ToleranceReport`, `FirstOrder`, `MonteCarlo`, `draw`, `draws`;
- streamed statistics: `Moments`;
- the robust-design map (`[study] robust`): `RobustMap` (`SampleReport.robust`);
- write-as-you-go and resume: `Checkpoint`, `resume_key`;
- screening and more sensitivity: `morris` (elementary effects, `morris_indices`, `trajectories`),
  `regression` (correlation and regression coefficients, `regression_indices`), `dgsm`
  (derivative-based measures from the exact gradients, `dgsm_indices`);
- correlated inputs: `iman_conover` (`[study.correlation]`);
- the stopping rule: `converged_sensitivity`, `converged_tolerance`, `Convergence`;
- Dakota's parameter studies: `parameter_study` (`vector`, `list`, `centered`);
- the `Study` of a call without `study=`, kept for the next identical call: `study_for`.

docs/methods/tolerance.md and docs/methods/sensitivity.md give the formulas;
docs/reference/file-format.md §17 the table.
"""

from .checkpoint import Checkpoint as Checkpoint
from .checkpoint import resume_key as resume_key
from .convergence import Convergence as Convergence
from .convergence import converged_sensitivity as converged_sensitivity
from .convergence import converged_tolerance as converged_tolerance
from .correlation import iman_conover as iman_conover
from .design import to_values as to_values
from .design import unit_blocks as unit_blocks
from .dgsm import DGSMIndices as DGSMIndices
from .dgsm import DGSMReport as DGSMReport
from .dgsm import dgsm as dgsm
from .dgsm import dgsm_indices as dgsm_indices
from .inputs import Range as Range
from .inputs import StudyInputs as StudyInputs
from .inputs import Tolerance as Tolerance
from .inputs import read_study as read_study
from .moments import Moments as Moments
from .morris import MorrisIndices as MorrisIndices
from .morris import MorrisReport as MorrisReport
from .morris import box_values as box_values
from .morris import morris as morris
from .morris import morris_indices as morris_indices
from .morris import trajectories as trajectories
from .parameter_studies import parameter_study as parameter_study
from .regression import RegressionIndices as RegressionIndices
from .regression import RegressionReport as RegressionReport
from .regression import regression as regression
from .regression import regression_indices as regression_indices
from .responses import Responses as Responses
from .robust import RobustMap as RobustMap
from .sampling import SampleReport as SampleReport
from .sampling import SensitivityReport as SensitivityReport
from .sampling import evaluate as evaluate
from .sampling import sample as sample
from .sampling import sensitivity as sensitivity
from .second_order import SecondOrder as SecondOrder
from .sobol import SobolAccumulator as SobolAccumulator
from .sobol import SobolIndices as SobolIndices
from .sobol import sobol_indices as sobol_indices
from .tolerance import FirstOrder as FirstOrder
from .tolerance import MonteCarlo as MonteCarlo
from .tolerance import Study as Study
from .tolerance import ToleranceReport as ToleranceReport
from .tolerance import draw as draw
from .tolerance import draws as draws
from .tolerance import study_for as study_for
from .tolerance import tolerance as tolerance
