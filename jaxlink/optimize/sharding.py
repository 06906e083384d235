"""Sharding of the design batch over all JAX devices (`jax.sharding`).

Every batched evaluation puts its leading (design) axis on a one-axis mesh named `designs`;
`jit` then partitions the computation so that each device solves its share of the designs.
Designs are independent, so the result does not depend on the number of devices (tested on CPU
with `XLA_FLAGS=--xla_force_host_platform_device_count=4`). Several GPUs of one host need
nothing more; several hosts call `jax.distributed.initialize()` first, after which
`jax.devices()` lists the devices of every process (docs/methods/optimize.md).
"""

from __future__ import annotations

import jax
import numpy as np
from jax.sharding import Mesh, NamedSharding, PartitionSpec


def design_sharding(devices=None) -> NamedSharding:
    devices = list(jax.devices() if devices is None else devices)
    mesh = Mesh(np.asarray(devices), ("designs",))
    return NamedSharding(mesh, PartitionSpec("designs"))


def pad_rows(x: np.ndarray, multiple: int) -> tuple[np.ndarray, int]:
    """Pad the leading axis to a multiple of `multiple` by repeating the first row; returns the
    padded array and the original length."""
    n = x.shape[0]
    m = -(-max(n, 1) // multiple) * multiple
    if m == n:
        return x, n
    pad = np.repeat(x[:1] if n else np.zeros((1,) + x.shape[1:], x.dtype), m - n, axis=0)
    return np.concatenate([x, pad], axis=0), n


def put(tree, sharding: NamedSharding):
    """Place every array of `tree` (leading axis = designs) on the mesh."""
    return jax.tree_util.tree_map(lambda a: jax.device_put(a, sharding), tree)
