"""Evaluation in fixed blocks: a function of many inputs called on blocks of `BLOCK` inputs, the
last one padded, so that every call runs one compiled program.

The designer's numbers evaluate the same quantities (the outputs' jets, cos μ, the reach margins)
at the samples of a turn and at a few inputs of each refinement step (golden sections,
bisections, the certificate's steps). In blocks, all of them are one program per quantity, which
`jaxlink.analysis.motion.prepare` can compile before the inputs are known, and an input's numbers
do not depend on the inputs evaluated beside it (XLA's code for another batch shape can differ in
the last bits: a sample and the same input in a refinement step did, when each had its own shape;
tests/test_check_start.py).
"""

from __future__ import annotations

import numpy as np

#: the inputs of one block
BLOCK = 128


def in_blocks(x, call, axis: int = 0) -> list:
    """`call` on the inputs `x` (M,) in blocks of `BLOCK` (the last one padded with x[0]; one
    compiled shape): each array `call` returns, its blocks joined along `axis` and cut to M, numpy."""
    x = np.asarray(x)
    n = x.shape[0]
    m = max(BLOCK, -(-n // BLOCK) * BLOCK)
    xs = np.concatenate([x, np.full(m - n, x[0] if n else 0.0, dtype=x.dtype)])
    parts = [[np.asarray(a) for a in call(xs[i:i + BLOCK])] for i in range(0, m, BLOCK)]
    return [np.take(np.concatenate([part[k] for part in parts], axis=axis), np.arange(n), axis=axis)
            for k in range(len(parts[0]))]
