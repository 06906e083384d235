"""Correlated inputs: a rank-correlation matrix between a study's inputs (`[study.correlation]`),
imposed on Monte Carlo and Latin-hypercube samples by the Iman–Conover method.

```toml
[study.correlation]         # Spearman rank correlations (the others 0)
crank = { rod = 0.6 }       # or: crank.rod = 0.6
rod = { B0_x = -0.3 }
```

**Iman–Conover** (Iman & Conover 1982), for a sample X (n × k) whose columns are to get the
target rank correlation C (k × k, symmetric, positive definite) without changing any column's
values:

1. the van der Waerden scores a_i = Φ⁻¹(i / (n + 1)), i = 1 … n, each column of S (n × k) a random
   permutation of them;
2. E the correlation matrix of S, Q its Cholesky factor (E = Q Qᵀ), P that of C: the scores
   S* = S Q⁻ᵀ Pᵀ have correlation matrix exactly C;
3. each column of X is reordered so that its ranks are those of the same column of S*.

The values of every column are unchanged (the same sorted values: the marginals, and a Latin
hypercube's one point per slice, are kept); only their pairing changes, so that the sample's
Spearman matrix is C up to sampling error (O(1/√n); the scores' Pearson correlation is C exactly,
their rank correlation close to it). A block of n ≤ k + 1 rows is left as it is.

Where it applies: the Monte Carlo draws of `tolerance` (each block of 1024 draws reordered on its
own stream; its first and second order use the Pearson correlation those draws have, `copula.py`)
and the designs of `sample` and `regression` with the `lhs` or `random` sampler (each
batch of designs reordered; reordering is within a column, so a Latin hypercube stays one). A
correlated input is a scalar factor (a range or a tolerance; not a circular zone). The Sobol',
Morris and derivative-based indices assume independent inputs: those methods refuse a correlation.
"""

from __future__ import annotations

from typing import Callable, Mapping

import numpy as np

#: the methods that accept a correlation
CORRELATED = ("tolerance", "sample", "regression")


def read_correlation(mech, inputs, raw, err: Callable) -> tuple:
    """The `(name, name, rho)` triples of `[study.correlation]` `raw` for the factors of `inputs`,
    checked (names, |rho| < 1, each pair once, methods, a positive-definite matrix); `err(mech,
    message, key)` makes the error raised."""
    if not isinstance(raw, Mapping):
        raise err(mech, f"[study.correlation] must be a table NAME = {{ NAME = rho }}, got {raw!r}", "correlation")
    if inputs.method not in CORRELATED:
        raise err(mech, f"a correlation applies to the {', '.join(CORRELATED)} methods (Monte Carlo and sampled "
                        f"designs); {inputs.method!r} assumes independent inputs", "correlation")
    if inputs.method != "tolerance" and inputs.sampler not in ("lhs", "random"):
        raise err(mech, f"a correlation is imposed on Latin-hypercube or random designs: set sampler = \"lhs\" or "
                        f"\"random\" (got {inputs.sampler!r})", "correlation")
    factors = {f.name: f for f in inputs.factors}
    seen: set = set()
    out = []
    for a, row in raw.items():
        if not isinstance(row, Mapping):
            raise err(mech, f"a correlation entry is NAME = {{ NAME = rho }}, got {a} = {row!r}", f"correlation.{a}")
        for b, rho in row.items():
            key = f"correlation.{a}.{b}"
            for n in (a, b):
                if n not in factors:
                    raise err(mech, f"'{n}' is not an input of the study; inputs: {', '.join(factors)}", key)
                if len(factors[n].parameters) != 1:
                    raise err(mech, f"'{n}' is a circular zone: only a scalar input can be correlated", key)
            if a == b:
                raise err(mech, f"'{a}' is correlated with itself (the diagonal is 1)", key)
            if isinstance(rho, bool) or not isinstance(rho, (int, float)) or not -1 < rho < 1:
                raise err(mech, f"a rank correlation lies strictly between −1 and 1, got {rho!r}", key)
            pair = frozenset((a, b))
            if pair in seen:
                raise err(mech, f"the pair {a}, {b} is given twice", key)
            seen.add(pair)
            out.append((a, b, float(rho)))
    triples = tuple(out)
    _, c = matrix(inputs, triples)
    if c.size and np.min(np.linalg.eigvalsh(c)) <= 1e-10:
        raise err(mech, "the rank-correlation matrix is not positive definite (no joint distribution has these "
                        "correlations): lower some of them", "correlation")
    return triples


def matrix(inputs, triples=None) -> tuple[np.ndarray, np.ndarray]:
    """(columns (k,) — the correlated inputs' indices in `inputs.parameters` —, C (k, k) their
    target rank-correlation matrix)."""
    triples = inputs.correlation if triples is None else triples
    names = list(dict.fromkeys(n for a, b, _ in triples for n in (a, b)))
    params = list(inputs.parameters)
    cols = np.asarray([params.index(n) for n in names], int)
    c = np.eye(len(names))
    for a, b, rho in triples:
        i, j = names.index(a), names.index(b)
        c[i, j] = c[j, i] = rho
    return cols, c


def iman_conover(x, target, rng) -> np.ndarray:
    """`x` (n, k) with each column reordered so that its rank correlation is `target` (k, k) (see
    the module doc); `rng` a numpy Generator (the scores' permutations)."""
    from scipy.stats import norm, rankdata

    x = np.asarray(x, float)
    n, k = x.shape
    if n <= k + 1:
        return x.copy()
    scores = norm.ppf(np.arange(1, n + 1) / (n + 1))
    s = np.stack([rng.permutation(scores) for _ in range(k)], axis=1)
    e = np.corrcoef(s, rowvar=False)
    q = np.linalg.cholesky(e)
    p = np.linalg.cholesky(np.asarray(target, float))
    s_star = np.linalg.solve(q, s.T).T @ p.T  # S Q⁻ᵀ Pᵀ = (Q⁻¹ Sᵀ)ᵀ Pᵀ
    out = np.empty_like(x)
    for j in range(k):
        ranks = rankdata(s_star[:, j], method="ordinal").astype(int) - 1
        out[:, j] = np.sort(x[:, j])[ranks]
    return out


def correlate(inputs, x, seed) -> np.ndarray:
    """`x` (n, T) (values or unit-cube points of the study's parameters) with its correlated columns
    reordered by Iman–Conover to the inputs' rank correlation (a Generator seeded with `seed`);
    `x` itself when the inputs have no correlation."""
    if not inputs.correlation:
        return x
    cols, c = matrix(inputs)
    out = np.array(x, float, copy=True)
    out[:, cols] = iman_conover(out[:, cols], c, np.random.default_rng(seed))
    return out
