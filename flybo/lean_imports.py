"""Open3D without its notebook viewer's web stack.

Importing `open3d` runs `open3d.visualization.draw_plotly`, which imports plotly and dash (and
through them IPython, Flask, narwhals...) for a notebook viewer the benchmark never draws with:
42 MiB more resident in every process that flies a run (plotly 7.1, dash 4.4) and a third of
Open3D's import time. `skip_open3d_web_viewer` installs an import hook that runs that one
module with stand-ins for `plotly`, `plotly.graph_objects` and `dash`, then takes the stand-ins
out of `sys.modules` again: a later `import plotly` gets the real package, and only calling
`open3d.visualization.draw_plotly` raises (naming why). Where plotly or dash is already
imported when Open3D is, the real one is used.
"""

from __future__ import annotations

import importlib.abc
import importlib.machinery
import sys
import types
from collections.abc import Sequence
from typing import Any

# The module that imports the web stack, and what it imports from it.
_VIEWER = "open3d.visualization.draw_plotly"
_STAND_INS = ("plotly", "plotly.graph_objects", "dash")


class _Unavailable:
    """Any name taken from a stand-in: using it raises."""

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        raise RuntimeError(
            "Open3D's plotly viewer is not loaded in FLYBO processes "
            "(flybo.lean_imports); use a FLYBO replay or the website's 3D view"
        )


class _StandIn(types.ModuleType):
    """A module whose every attribute is `_Unavailable`."""

    def __getattr__(self, name: str) -> Any:
        if name.startswith("__"):
            raise AttributeError(name)
        return _Unavailable


class _ViewerLoader(importlib.abc.Loader):
    """Runs the viewer's module with the stand-ins in place, then removes them."""

    def __init__(self, loader: importlib.abc.Loader) -> None:
        self._loader = loader

    def create_module(self, spec: importlib.machinery.ModuleSpec) -> types.ModuleType | None:
        return self._loader.create_module(spec)

    def exec_module(self, module: types.ModuleType) -> None:
        placed = [name for name in _STAND_INS if name not in sys.modules]
        for name in placed:
            sys.modules[name] = _StandIn(name)
        if "plotly" in placed and "plotly.graph_objects" in placed:
            sys.modules["plotly"].graph_objects = sys.modules["plotly.graph_objects"]  # type: ignore[attr-defined]
        try:
            self._loader.exec_module(module)
        finally:
            for name in placed:
                sys.modules.pop(name, None)


class _ViewerFinder(importlib.abc.MetaPathFinder):
    """Finds the viewer's module as the path finder does, with `_ViewerLoader` around its
    loader; every other import is left to the finders after it."""

    def find_spec(self, fullname: str, path: Sequence[str] | None,
                  target: types.ModuleType | None = None,
                  ) -> importlib.machinery.ModuleSpec | None:
        if fullname != _VIEWER:
            return None
        spec = importlib.machinery.PathFinder.find_spec(fullname, path, target)
        if spec is None or spec.loader is None:
            return None
        spec.loader = _ViewerLoader(spec.loader)
        return spec


def skip_open3d_web_viewer() -> None:
    """Install the hook (once); it acts only when Open3D is imported after it."""
    if not any(isinstance(f, _ViewerFinder) for f in sys.meta_path):
        sys.meta_path.insert(0, _ViewerFinder())
