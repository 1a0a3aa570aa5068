"""A module that takes a second to import, as the plotting code takes its time in the figure process."""

import time

time.sleep(1.0)


def draw() -> None:
    """Nothing: the module is here for its import."""
