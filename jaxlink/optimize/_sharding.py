"""The design-batch sharding of the search lives in the engine (`jaxlink._sharding`)."""

from .._sharding import design_sharding, pad_rows, put

__all__ = ["design_sharding", "pad_rows", "put"]
