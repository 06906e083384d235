"""Sharding of the design batch over all JAX devices (`jax.sharding`).

Every batched evaluation puts its leading (design) axis on a one-axis mesh named `designs`;
`jit` then partitions the computation so that each device solves its share of the designs.
Designs are independent, so the result does not depend on the number of devices (tested on CPU
with `XLA_FLAGS=--xla_force_host_platform_device_count=4`). Several GPUs of one host need
nothing more; several processes or hosts split each batch between them first
(`distributed.py`), each sharding its share over its own devices.
"""

from __future__ import annotations

import jax
import numpy as np
from jax.sharding import Mesh, NamedSharding, PartitionSpec


def design_sharding(devices=None) -> NamedSharding:
    """The design axis over `devices` (default: this process's devices; several processes split
    a batch between them first, `distributed.py`)."""
    devices = list(jax.local_devices() if devices is None else devices)
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


# positions (design × sample × circuit) per compiled batch: on a CPU enough to hide the per-call
# overhead (measured: 256 designs × 36 samples ran at 2.8e6 positions/s, 4096 × 36 at 7.2e6 on 2
# cores); on an accelerator enough to fill it (an H100 ran Monte Carlo 18× faster with 1e5 designs
# per batch than with 256), bounded by a quarter of its memory.
CPU_POSITIONS = 1 << 18
ACCELERATOR_POSITIONS = 1 << 23


def default_chunk(positions_per_design: int, values_per_position: int, devices=None) -> int:
    """Designs per batch for this machine: the largest power of two (times the device count) of at
    most `CPU_POSITIONS` positions on a CPU and `ACCELERATOR_POSITIONS` on a GPU/TPU, fewer
    where a quarter of the device's memory would not hold them (≈ 16 float64 values per solved
    value: `values_per_position` = unknowns + 2 × points)."""
    devices = list(jax.local_devices() if devices is None else devices)
    target = CPU_POSITIONS if devices[0].platform == "cpu" else ACCELERATOR_POSITIONS
    try:
        limit = int(devices[0].memory_stats()["bytes_limit"])
        target = min(target, limit // 4 // (16 * 8 * max(1, values_per_position)))
    except Exception:  # no memory statistics (the CPU): the target stands
        pass
    designs = max(1, target // max(1, positions_per_design))
    chunk = 1
    while 2 * chunk <= designs:
        chunk *= 2
    return -(-chunk // len(devices)) * len(devices)
