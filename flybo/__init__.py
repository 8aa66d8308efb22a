"""FLYBO: an open benchmark for autonomous exploration planners of flying robots."""

from flybo.cpu_kernels import pin_cpu_kernels

# Before anything imports NumPy: the same kernels on every machine (`flybo.cpu_kernels`).
pin_cpu_kernels()

__version__ = "0.1.0"
