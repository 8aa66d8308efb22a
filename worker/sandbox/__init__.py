"""Running planner code in an isolated process (see `docs/sandbox.md`).

`SandboxedPlanner` stands in for a planner inside the episode runner; the code runs in
`worker.sandbox.child`, in its own process with no network, an almost empty filesystem view,
an empty environment and resource limits, talking JSON over a pipe.
"""
