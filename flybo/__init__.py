"""FLYBO: an open benchmark for autonomous exploration planners of flying robots."""

from flybo.blas import pin_blas_kernels

# Before anything imports NumPy: the same kernels on every machine (`flybo.blas`).
pin_blas_kernels()

__version__ = "0.1.0"
