"""`python -m flybo` is the `flybo` command."""

from flybo.cli import main

main()
