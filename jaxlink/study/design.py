"""The designs a study evaluates: points of the unit cube from `scipy.stats.qmc` (or numpy's
generator), mapped to the studied parameters' values (file units), and the full-factorial grid.

**Samplers** (`[study] sampler`), d the number of studied parameters, seeded with `seed`:

- `"sobol"`: scrambled Sobol' (`qmc.Sobol(d, scramble=True)`, Owen scrambling with a digital
  shift); best balanced for n a power of two (n is taken as given; scipy's balance warning is
  silenced);
- `"halton"`: scrambled Halton (`qmc.Halton(d, scramble=True)`);
- `"lhs"`: Latin hypercube (`qmc.LatinHypercube(d)`: one point in each of n equal slices of every
  axis); drawn at once (n × d numbers in memory), the others in blocks;
- `"random"`: independent uniform draws (`numpy.random.default_rng(seed).random`).

**The map u ∈ [0, 1)^d → x** (`to_values`, per factor of `StudyInputs.factors`):

- a range [low, high]: x = low + u (high − low) (uniform);
- a uniform tolerance ±t around the nominal x₀: x = x₀ + t (2u − 1);
- a normal tolerance: x = x₀ + σ Φ⁻¹(u) (u clipped to [1e−12, 1 − 1e−12]);
- a triangular or truncated-normal tolerance: x = x₀ + its inverse CDF at u
  (`distributions.deviations`);
- a circular zone of radius r (two columns u₁, u₂): uniform in the disc, (x, y) = (x₀, y₀) +
  r √u₁ (cos 2πu₂, sin 2πu₂); normal: each coordinate x₀ + σ Φ⁻¹(u).

**The grid** (`grid_values`): each range's `levels` equally spaced values from low to high
(both included; one level: the midpoint), every combination, the last parameter varying fastest (C order).
"""

from __future__ import annotations

import warnings

import numpy as np

from .inputs import Range, StudyInputs

#: the unit-cube points drawn per call (the blocks of `unit_blocks`)
UNIT_BLOCK = 1 << 16


def unit_blocks(sampler: str, d: int, n: int, seed: int, block: int = UNIT_BLOCK):
    """Yield the first `n` points of the `sampler`'s sequence in [0, 1)^d, in blocks of at most
    `block` rows (the same points whatever `block`; a Latin hypercube is drawn at once)."""
    from scipy.stats import qmc

    rng = np.random.default_rng(seed)
    if sampler == "lhs":
        u = qmc.LatinHypercube(d, seed=rng).random(n) if n else np.zeros((0, d))
        for s in range(0, n, block):
            yield u[s:s + block]
        return
    engine = None
    if sampler == "sobol":
        engine = qmc.Sobol(d, scramble=True, seed=rng)
    elif sampler == "halton":
        engine = qmc.Halton(d, scramble=True, seed=rng)
    elif sampler != "random":
        raise ValueError(f"unknown sampler {sampler!r}")
    for s in range(0, n, block):
        k = min(block, n - s)
        if engine is None:
            yield rng.random((k, d))
        else:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", UserWarning)  # Sobol' balance: n not a power of two
                yield engine.random(k)


def to_values(inputs: StudyInputs, x0, u) -> np.ndarray:
    """(n, T) the studied parameters' values (file units) at the unit-cube points `u` (n, T) (see
    the module doc); `x0` (T,) the nominal values."""
    from scipy.stats import norm

    u = np.asarray(u, float)
    x0 = np.asarray(x0, float)
    out = np.empty_like(u)
    j = 0
    for f in inputs.factors:
        k = len(f.parameters)
        c = u[:, j:j + k]
        if isinstance(f, Range):
            out[:, j] = f.low + c[:, 0] * (f.high - f.low)
        elif f.distribution == "uniform" and f.zone:
            r = f.half_width * np.sqrt(c[:, 0])
            a = 2.0 * np.pi * c[:, 1]
            out[:, j] = x0[j] + r * np.cos(a)
            out[:, j + 1] = x0[j + 1] + r * np.sin(a)
        elif f.distribution == "uniform":
            out[:, j] = x0[j] + f.half_width * (2.0 * c[:, 0] - 1.0)
        elif f.distribution in ("triangular", "truncated-normal"):
            from .distributions import deviations

            out[:, j] = x0[j] + deviations(f.distribution, c[:, 0], f.half_width, f.sigma, f.k)
        else:
            out[:, j:j + k] = x0[j:j + k] + f.sigma * norm.ppf(np.clip(c, 1e-12, 1.0 - 1e-12))
        j += k
    return out


def grid_shape(inputs: StudyInputs) -> tuple:
    """The grid's levels per range."""
    return tuple(r.levels for r in inputs.ranges)


def grid_axes(inputs: StudyInputs) -> list:
    """Each range's levels (file units)."""
    return [np.linspace(r.low, r.high, r.levels) if r.levels > 1 else np.asarray([0.5 * (r.low + r.high)])
            for r in inputs.ranges]


def grid_values(inputs: StudyInputs, start: int, stop: int) -> np.ndarray:
    """Rows `start` … `stop − 1` (C order) of the full-factorial grid (n, T) (file units)."""
    axes = grid_axes(inputs)
    idx = np.unravel_index(np.arange(start, stop), grid_shape(inputs))
    return np.stack([a[i] for a, i in zip(axes, idx)], axis=1)
