"""Test configuration: float64 on (the library itself follows the dtype of its inputs)."""

import jax

jax.config.update("jax_enable_x64", True)
