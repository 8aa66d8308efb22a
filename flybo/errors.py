"""The command line's one error type, shared by `flybo.cli` and `flybo.service_cli`."""

from __future__ import annotations


class CliError(Exception):
    """A problem with the command line's input, reported in one line."""
