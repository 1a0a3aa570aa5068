"""The scenario-free part of the calibrations' stability test: the number of windows and the diffuse prior.

Each scenario runs its filter on K windows of one log, each from its own prior, so that no window
inherits another's posterior and the K errors are independent (accel-gps:
:mod:`kalcal.scenarios.accel_gps.windows`, scale-bias: :mod:`kalcal.scenarios.scale_bias.windows`); the
windows' estimates are compared by :mod:`kalcal.calibration.stability`. What is the same for every
scenario is here: ``--windows`` checked (:func:`check_windows`), and the width of a window's diffuse
prior, :data:`DIFFUSE` sqrt(K) times the whole log's final sigma, so that at most 1e-6 of a window's
information comes from it and the window's estimate is its data's.
"""

from __future__ import annotations

import numpy as np

from kalcal.errors import ConfigError

#: a window's diffuse prior std, over sqrt(K) times the whole log's final sigma
DIFFUSE = 1e3


def check_windows(windows) -> int:
    """``--windows`` as a whole number >= 1 (1: no stability test)."""
    if isinstance(windows, bool) or not isinstance(windows, (int, np.integer)) or windows < 1:
        raise ConfigError(f"--windows: expected a whole number of windows (>= 1; 1 turns the test off), got {windows!r}")
    return int(windows)
