"""``python -m braidsim`` runs the command line."""

from braidsim.cli import main

main()
