"""``python -m kalcal.cli``: the ``kalcal`` command."""

from kalcal.cli import main

if __name__ == "__main__":
    main()
