"""Parameter studies on the batched, differentiable evaluator (`jaxlink study`).

This step: the tolerance analysis around one design — exact first order (RSS σ, linear worst
case, importance factors) from the Jacobian of the responses over the whole cycle, and Monte
Carlo with the tolerances' distributions, streamed; feasibility over the whole cycle counted.

- inputs: `read_study`, `StudyInputs`, `Tolerance` (the `[study]` table);
- responses: `Responses` (points' x, y over the cycle, stroke/swing, max speed/acceleration);
- the analysis: `tolerance`, `Study`, `ToleranceReport`, `FirstOrder`, `MonteCarlo`, `draw`, `draws`;
- streamed statistics: `Moments`.

docs/methods/tolerance.md gives the formulas; docs/reference/file-format.md §17 the table.
"""

from .inputs import StudyInputs as StudyInputs
from .inputs import Tolerance as Tolerance
from .inputs import read_study as read_study
from .moments import Moments as Moments
from .responses import Responses as Responses
from .tolerance import FirstOrder as FirstOrder
from .tolerance import MonteCarlo as MonteCarlo
from .tolerance import Study as Study
from .tolerance import ToleranceReport as ToleranceReport
from .tolerance import draw as draw
from .tolerance import draws as draws
from .tolerance import tolerance as tolerance
