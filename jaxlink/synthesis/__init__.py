"""Path synthesis: a linkage — its topology and its dimensions — whose point follows a target path.

- `target`: the target curve read from CSV, NPY or SVG (timed: each point at an input angle); arclength resampling;
- `distance`: the distance (the phase-free symmetric chamfer of the normalised curves at the best
  rotation, `match`), LInK's metric (`link_chamfer`), the placement, the ordered distance, the
  smooth surrogate;
- `topology`: one-DOF revolute linkages grown by dyads (four-bar, Watt and Stephenson six-bars, eight-bars);
- `tracer`: batched (JAX) and exact (NumPy) tracing from a pose, the dyads' reach margins;
- `assembly`: the check that a candidate assembles over its whole interval on its branch;
- `size`: a design's size in extents of the target, and the bound a search keeps to (`max_size`);
- `transmission`: a design's least transmission angle, and the floor a search keeps to (`min_transmission`);
- `bounds`: the designer's bounds, on by default (30°, 3 extents, 3 extents), and what a design breaks;
- `pareto`: the Pareto front of distance, joints, transmission angle and size; the simplest design that fits;
- `search`: screen → rank → refine → score rounds (`block_caps`, `default_blocks`: the blocks a
  platform's batches are cut into);
- `mechanism`: a candidate as a sketch file; `api`: `synthesize`.

`jaxlink.synthesize` is the entry point; `jaxlink.synthesis.distance.match` the metric.
"""

from .api import Design as Design
from .api import Synthesis as Synthesis
from .api import synthesize as synthesize
from .bounds import MAX_PIVOT as MAX_PIVOT
from .bounds import MAX_SIZE as MAX_SIZE
from .bounds import MIN_TRANSMISSION as MIN_TRANSMISSION
from .distance import Match as Match
from .distance import link_chamfer as link_chamfer
from .distance import match as match
from .search import block_caps as block_caps
from .search import default_blocks as default_blocks
from .target import Target as Target
from .target import load_target as load_target
from .target import make_target as make_target
