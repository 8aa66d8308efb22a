"""FLYBO: an open benchmark for autonomous exploration planners of flying robots."""

__version__ = "0.1.0"
