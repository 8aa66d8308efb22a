"""The planner API and registry, shared planning services, and the built-in planners."""
