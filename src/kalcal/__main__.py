"""``python -m kalcal``: the ``kalcal`` command."""

from kalcal.cli import run

if __name__ == "__main__":
    run()
