"""flybo.lean_imports: Open3D imported without its notebook viewer's web stack, each case in a
fresh interpreter (the hook acts when Open3D is first imported)."""

from __future__ import annotations

import subprocess
import sys
import textwrap


def _run(code: str) -> str:
    done = subprocess.run([sys.executable, "-c", textwrap.dedent(code)], capture_output=True,
                          text=True, timeout=120, check=False)
    assert done.returncode == 0, done.stderr
    return done.stdout.strip()


def test_open3d_loads_without_plotly_and_dash_which_stay_importable() -> None:
    out = _run("""
        import sys
        import flybo
        import open3d
        from sim.open3d_any import o3d
        print(sorted(n for n in ("plotly", "plotly.graph_objects", "dash", "IPython")
                     if n in sys.modules))
        scene = o3d.t.geometry.RaycastingScene()  # Open3D itself works
        try:
            open3d.visualization.draw_plotly([])
        except RuntimeError as exc:
            print("viewer:", "not loaded" in str(exc))
        import plotly.graph_objects as go
        import dash
        print(hasattr(go.Figure, "add_trace"), dash.Dash.__module__.startswith("dash"))
    """)
    assert out.splitlines() == ["[]", "viewer: True", "True True"]


def test_plotly_imported_first_is_the_one_open3d_gets() -> None:
    out = _run("""
        import sys
        import flybo
        import plotly.graph_objects as go
        import open3d
        print(sys.modules["open3d.visualization.draw_plotly"].go is go)
    """)
    assert out == "True"
