"""A stand-in for a prepared accel-gps log: a given log-likelihood and fixed normalized innovations, for
checks of the fit's logic that a full filter run would make slow."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
from scipy import stats


class FakeLog:
    """``loglik(values)`` given; ``calibrate`` returns ``normalized`` (K, 2) as the innovations, the gate
    rejecting those whose NIS exceeds chi2.ppf(gate, 2); ``calls`` records every calibration's values."""

    def __init__(self, loglik, normalized, starts):
        self._loglik, self.normalized, self.starts, self.calls = loglik, normalized, dict(starts), []
        self.fixes = normalized.shape[0]

    def loglik(self, values, *, gate=None, rejected=None):
        return float(self._loglik({**self.starts, **values}))

    def calibrate(self, values, *, gate=None):
        self.calls.append(dict(values))
        k = self.fixes
        rejected = None
        if gate is not None:
            rejected = np.sum(self.normalized**2, axis=1) > stats.chi2.ppf(gate, 2)
        return SimpleNamespace(time=np.arange(k, dtype=float), normalized_innovations=self.normalized, rejected=rejected,
                               rejected_rows=None if rejected is None else np.flatnonzero(rejected) + 1, skip=0,
                               bias=np.zeros(k), std=np.ones((k, 3)))

    def settings_value(self, key):
        if key not in self.starts and key == "filter.bias_correlation_time":
            return 0.0  # not given: a bias without a correlation time (no Gauss-Markov bias)
        return self.starts[key]

    def unit(self, key):
        return "m"
