"""Open3D typed as Any: its bundled stubs reject the NumPy arrays its functions accept."""

from __future__ import annotations

import importlib
from typing import Any

o3d: Any = importlib.import_module("open3d")
o3c: Any = importlib.import_module("open3d.core")
