"""Objective registry: each objective maps the traced path of the chosen point to a number.

An objective is built from the `Problem` by a factory registered under its name
(`register("name", factory, keys=(...))`); the factory returns an `Objective`:

- `order`: derivatives of the path the objective needs (0: positions; 2: + d/dφ, d²/dφ²),
- `value(path)`: the objective evaluated exactly at the sampled path (ranking, reports),
- `smooth(path)`: a smoothed version with useful gradients (the gradient search),
- `metrics(path)`: named numbers for the report;
- optionally `constraints(path) -> (f, c, value)`: a smooth objective f and constraint values
  c (K,) with c[:equalities] = 0 and c[equalities:] ≤ 0 wanted (normalized), and the exact
  `value(path)` from the same intermediates, for the constrained gradient solver
  (`gradient_solver = "al-lbfgs"`);
- optionally `rank(path) -> (value, rank)`: the exact value and the value by which the
  constrained gradient search picks its starts from the presample (default: `value` for both).

`path` is a `PathData` in the file's units (lengths in `length_unit`, derivatives per radian of
input), with the solved configuration `q` and the parameters `p` (SI) for objectives that need
more than the point's path.

**Registration is explicit.** Nothing registers itself when it is imported. The first time the
registry is asked (`in`, iteration, `known_keys`, `build`, `register`), it calls
`register_objectives(register)` of each module of a fixed list, in this order:

- `jaxlink/optimize/objectives/path.py`: the generic path objectives `points` and `ellipse`;
- `jaxlink/scenes/sewing_feed.py`: `feed` (the feed-dog path of the sewing-machine feed six-bar);
- `jaxlink/scenes/needle_dwell.py`: `dwell` (the dwell of a needle stroke).

A further objective plugs in with `register(name, factory, keys=...)`.
"""

from __future__ import annotations

from typing import Callable, Iterable

from .base import Objective as Objective
from .base import PathData as PathData
from .base import number as number
from .base import to_python as to_python


def _builtin_modules() -> tuple:
    """The modules whose `register_objectives(register)` fills the registry (fixed, in order)."""
    from ...scenes import needle_dwell, sewing_feed
    from . import path

    return (path, sewing_feed, needle_dwell)


class Registry:
    """Objective factories by name and the `[optimize]` keys each reads.

    The built-in objectives (`_builtin_modules`) are registered on first use."""

    def __init__(self, builtins: Callable[[], Iterable] = _builtin_modules):
        self._factories: dict[str, Callable] = {}
        self._keys: dict[str, tuple] = {}
        self._builtins = builtins
        self._loaded = False

    def _load(self) -> None:
        if not self._loaded:
            self._loaded = True  # before the calls: a built-in module may ask the registry
            for module in self._builtins():
                module.register_objectives(self._add)

    def _add(self, name: str, factory: Callable, *, keys: Iterable[str] = ()) -> Callable:
        if not isinstance(name, str) or not name:
            raise ValueError(f"an objective name must be a non-empty string, got {name!r}")
        if name in self._factories:
            raise ValueError(f"objective '{name}' is already registered")
        self._factories[name] = factory
        self._keys[name] = tuple(keys)
        return factory

    def register(self, name: str, factory: Callable, *, keys: Iterable[str] = ()) -> Callable:
        """Register `factory(problem) -> Objective` under `name`; `keys` are the `[optimize]`
        keys it reads (so that the parser accepts them). A name can be registered once."""
        self._load()
        return self._add(name, factory, keys=keys)

    def __contains__(self, name) -> bool:
        self._load()
        return name in self._factories

    def __iter__(self):
        self._load()
        return iter(list(self._factories))

    def keys_of(self, name: str) -> tuple:
        """The `[optimize]` keys that objective `name` reads."""
        self._load()
        return self._keys[name]

    def known_keys(self) -> set:
        self._load()
        return {k for ks in self._keys.values() for k in ks}

    def build(self, problem) -> Objective:
        self._load()
        return self._factories[problem.objective](problem)


OBJECTIVES = Registry()


def register(name: str, factory: Callable, *, keys: Iterable[str] = ()) -> Callable:
    """Register `factory(problem) -> Objective` under `name` in `OBJECTIVES`; `keys`: the
    `[optimize]` keys it reads. Returns `factory`."""
    return OBJECTIVES.register(name, factory, keys=keys)
