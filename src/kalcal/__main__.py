"""``python -m kalcal``: the ``kalcal`` command."""

from kalcal.cli import main

main()
