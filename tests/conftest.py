"""Test configuration: float64 on (the library itself follows the dtype of its inputs)."""

import os

import jax

# The command line turns on JAX's persistent compilation cache (jaxlink/cache.py); tests call it
# in-process, so keep them hermetic: no cache unless the run asks for one.
os.environ.setdefault("JAXLINK_CACHE_DIR", "")

jax.config.update("jax_enable_x64", True)
