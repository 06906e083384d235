"""Small dense linear solves, unrolled so that XLA fuses them under `vmap`.

Batched `jnp.linalg.solve` on tiny systems calls LAPACK per system and breaks XLA fusion
(measured 5× slower than an unrolled elimination on the feed six-bar's 4 × 4 systems). For the n ≤ 8 systems of
loop closure (2 equations per loop) we unroll Gaussian elimination with partial pivoting in
Python: every operation is elementwise, so a `vmap` over positions and designs becomes one
fused kernel.

Each solve also returns a pivot ratio, a cheap singularity indicator. `solve_small` normalizes it
by the largest entry by default (kinetostatics, whose system is scaled to O(1)) or, with
`scaling="columns"`, by each pivot's column norm (the pivots of the column-equilibrated matrix):
invariant under the units of the unknowns, as the assembly solve needs (an angle's column of Φ_q
is ~ a length, a slider length's ~ 1). `solve_2x2` and `solve_block_lower` use the column-scaled
ratio and also return the sign of det of each diagonal block (a dyad's circuit).
"""

from __future__ import annotations

import jax.numpy as jnp

UNROLL_MAX = 8


def solve_small(a, b, *, scaling: str = "matrix", signs: bool = False):
    """Solve `a x = b` for one small system (vmap for batches).

    **Arguments:**

    - `a`: (n, n) matrix.
    - `b`: (n,) right-hand side.
    - `scaling`: how the pivot ratio is normalized (static). `"matrix"`: min |pivot| / max |a_ij|
      (≈ 1/condition number when the entries share a unit). `"columns"`: min_k |pivot_k| /
      ‖column k‖∞, the pivots of the column-equilibrated matrix (partial pivoting by rows is
      unchanged by column scaling): invariant under a scaling of the unknowns, so columns of
      different units (an angle's column ~ a length, a slider length's ~ 1) do not make a healthy
      matrix look singular. For n = 2 it is |det| / (‖col 0‖∞ ‖col 1‖∞), within a factor 2 of
      the sine of the angle between the columns.

    **Returns:** `(x, pivot_ratio)`: the solution and the pivot ratio, a cheap singularity
    indicator (0 for a singular matrix, in which case `x` holds non-finite values); with
    `signs=True` also the sign of det a (from the pivots and the row swaps).
    """
    out = _solve_small(a, b, scaling)
    return out if signs else out[:2]


def _solve_small(a, b, scaling):
    n = a.shape[-1]
    tiny = jnp.finfo(a.dtype).tiny
    if n > UNROLL_MAX:
        x = jnp.linalg.solve(a, b)
        if scaling == "columns":
            a = a / jnp.maximum(jnp.max(jnp.abs(a), axis=0), tiny)
        s = jnp.linalg.svd(a, compute_uv=False)
        return x, s[-1] / jnp.maximum(s[0], tiny), jnp.sign(jnp.linalg.det(a))
    rows = [[a[i, j] for j in range(n)] for i in range(n)]
    rhs = [b[i] for i in range(n)]
    if scaling == "columns":
        col_norm = [jnp.maximum(jnp.max(jnp.abs(a[:, j])), tiny) for j in range(n)]
    else:
        scale = jnp.maximum(jnp.max(jnp.abs(a)), tiny)
    min_piv = None
    sign = None
    for k in range(n):
        # partial pivoting: bring the largest |a_ik| (i >= k) to row k, by selects
        if k < n - 1:
            best = jnp.abs(rows[k][k])
            best_i = jnp.zeros((), dtype=jnp.int32) + k
            for i in range(k + 1, n):
                v = jnp.abs(rows[i][k])
                better = v > best
                best = jnp.where(better, v, best)
                best_i = jnp.where(better, i, best_i)
            new_k = [_pick(rows, best_i, j, k, n) for j in range(k, n)]
            new_b_k = _pick_vec(rhs, best_i, k, n)
            for i in range(k + 1, n):
                swap = best_i == i
                for j in range(k, n):
                    rows[i][j] = jnp.where(swap, rows[k][j], rows[i][j])
                rhs[i] = jnp.where(swap, rhs[k], rhs[i])
            for j in range(k, n):
                rows[k][j] = new_k[j - k]
            rhs[k] = new_b_k
            flip = jnp.where(best_i == k, 1.0, -1.0)
            sign = flip if sign is None else sign * flip
        piv = rows[k][k]
        apiv = jnp.abs(piv) / col_norm[k] if scaling == "columns" else jnp.abs(piv)
        min_piv = apiv if min_piv is None else jnp.minimum(min_piv, apiv)
        inv = 1.0 / piv
        for i in range(k + 1, n):
            f = rows[i][k] * inv
            for j in range(k + 1, n):
                rows[i][j] = rows[i][j] - f * rows[k][j]
            rhs[i] = rhs[i] - f * rhs[k]
    x = [None] * n
    for i in range(n - 1, -1, -1):
        s = rhs[i]
        for j in range(i + 1, n):
            s = s - rows[i][j] * x[j]
        x[i] = s / rows[i][i]
    det_sign = jnp.sign(rows[0][0]) if sign is None else sign * jnp.sign(rows[0][0])
    for k in range(1, n):
        det_sign = det_sign * jnp.sign(rows[k][k])
    ratio = min_piv if scaling == "columns" else min_piv / scale
    return jnp.stack(x), ratio, det_sign.astype(a.dtype)


def _pick(rows, idx, j, k, n):
    out = rows[k][j]
    for i in range(k + 1, n):
        out = jnp.where(idx == i, rows[i][j], out)
    return out


def _pick_vec(v, idx, k, n):
    out = v[k]
    for i in range(k + 1, n):
        out = jnp.where(idx == i, v[i], out)
    return out


def solve_2x2(a00, a01, a10, a11, b0, b1, ok=None):
    """Cramer's rule for one 2×2 system; returns (x0, x1, ratio, sign of det) with the
    column-scaled pivot ratio |det| / (‖col 0‖∞ ‖col 1‖∞) (see `solve_small`, `scaling="columns"`).
    Where `ok` (a boolean scalar) is False, det is taken as 1 (no division by zero; the caller
    discards x there)."""
    det = a00 * a11 - a01 * a10
    c0 = jnp.maximum(jnp.abs(a00), jnp.abs(a10))
    c1 = jnp.maximum(jnp.abs(a01), jnp.abs(a11))
    inv = 1.0 / (det if ok is None else jnp.where(ok, det, 1.0))
    ratio = jnp.abs(det) / jnp.maximum(c0 * c1, jnp.finfo(jnp.result_type(det)).tiny)
    return (a11 * b0 - a01 * b1) * inv, (a00 * b1 - a10 * b0) * inv, ratio, jnp.sign(det)


def _forward_substitution(entry, b, blocks, ok=None):
    """Forward substitution over the diagonal blocks `blocks` of a block lower-triangular matrix
    given entry by entry (`entry(r, c)`; only the diagonal blocks and the entries left of them are
    asked for): Cramer's rule on 2×2 blocks, `solve_small` on larger ones (the identity where `ok`
    is False). Returns (list of the x_c, pivot ratio per block, sign of det per block)."""
    n = sum(len(cols) for _, cols in blocks)
    x = [None] * n
    ratios, signs = [], []
    done: list = []
    for rows, cols in blocks:
        rhs = []
        for r in rows:
            s = b[r]
            for j in done:
                s = s - entry(r, j) * x[j]
            rhs.append(s)
        if len(cols) == 2 and len(rows) == 2:
            (r0, r1), (c0, c1) = rows, cols
            x[c0], x[c1], rr, sg = solve_2x2(entry(r0, c0), entry(r0, c1), entry(r1, c0), entry(r1, c1),
                                             rhs[0], rhs[1], ok)
        else:
            eye = ok is not None
            sub = jnp.stack([jnp.stack([jnp.where(ok, entry(r, c), float(i == k)) if eye else entry(r, c)
                                        for k, c in enumerate(cols)]) for i, r in enumerate(rows)])
            xs, rr, sg = _solve_small(sub, jnp.stack(rhs), "columns")
            for k, c in enumerate(cols):
                x[c] = xs[k]
        ratios.append(rr)
        signs.append(sg)
        done.extend(cols)
    return x, ratios, signs


def solve_block_lower(a, b, blocks):
    """Solve `a x = b` when `a` is block lower-triangular in the order `blocks`.

    `blocks` is a tuple of `(row_indices, col_indices)` (as from `_structure.blocks`, with loop ℓ
    giving rows 2ℓ, 2ℓ+1): rows of block i involve only the columns of blocks ≤ i. Forward
    substitution with Cramer's rule on 2×2 diagonal blocks and `solve_small` on larger ones.
    Returns `(x, pivot_ratio, signs)`: the pivot ratio column-scaled (`solve_small`,
    `scaling="columns"`) and the smallest over the diagonal blocks; the sign of det of every
    diagonal block, shape (n_blocks,) (for a dyad, which of its two assembly branches — circuits —
    the matrix belongs to)."""
    x, ratios, signs = _forward_substitution(lambda r, c: a[r, c], b, blocks)
    ratio = ratios[0]
    for rr in ratios[1:]:
        ratio = jnp.minimum(ratio, rr)
    return jnp.stack(x), ratio, jnp.stack(signs)


def solve_block_lower_scalars(entry, b, blocks, ok=None):
    """`solve_block_lower` on scalars: `entry(r, c)` gives a_rc (only the diagonal blocks and the
    entries left of them are asked for), `b` is a sequence of scalars; returns the list of the
    x_c. No array is assembled or indexed, so that under `vmap` and reverse-mode AD every
    operation stays elementwise (the transpose of indexing an array is a pad of the whole vector
    per use). Cramer's rule on 2×2 diagonal blocks, `solve_small` on larger ones. Where `ok`
    (a boolean scalar) is False the diagonal blocks are replaced by regular ones (det 1 on 2×2
    blocks, the identity on larger ones), so that no division by zero occurs: the caller discards
    x there. (The pivot ratios and signs are not computed: unused, XLA drops them.)"""
    return _forward_substitution(entry, b, blocks, ok)[0]
