"""`python -m clutterbench.cli`: the `clutterbench` command."""

from clutterbench.cli import main

main()
