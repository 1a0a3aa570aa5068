"""Small models that several filter tests share."""

from __future__ import annotations

import numpy as np

from kalcal.core.model import LinearGaussianModel


def blind_model() -> LinearGaussianModel:
    """A constant-velocity model with H = 0: its filter only propagates (the degenerate oracle)."""
    return LinearGaussianModel(
        phi=[[1.0, 0.5], [0.0, 1.0]],
        gamma=[[0.125], [0.5]],
        h=np.zeros((1, 2)),
        w=[[0.2]],
        v=[[1.0]],
        x0=[1.0, -2.0],
        m0=[[2.0, 0.3], [0.3, 1.0]],
        steps_per_update=4,
        sample_period=0.5,
    )
