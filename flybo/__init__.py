"""FLYBO: an open benchmark for autonomous exploration planners of flying robots."""

from flybo.cpu_kernels import pin_cpu_kernels
from flybo.kernel_cache import drop_stale_kernels
from flybo.lean_imports import skip_open3d_web_viewer

# Before anything imports NumPy: the same kernels on every machine (`flybo.cpu_kernels`).
pin_cpu_kernels()
# Before anything imports Open3D: not its notebook viewer's web stack (`flybo.lean_imports`).
skip_open3d_web_viewer()
# Before any kernel loads from numba's cache: none compiled against sources since changed
# (`flybo.kernel_cache`).
drop_stale_kernels()

__version__ = "0.1.0"
