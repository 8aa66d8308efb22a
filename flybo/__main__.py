"""`python -m flybo` is the `flybo` command (the installation check first)."""

from flybo.distribution import main

main()
