"""In-browser 3D replay of runs with viser (`docs/replay.md`).

`app.start_viewer` / `app.serve_viewer` run the viewer; `routes.router` adds the website's
``/runs/{id}/replay`` link to it.
"""
