"""``python -m fdbench.cli``: the command line."""

from . import main

main()
