"""The former home of the Kalman steps, kept importable for the Monte Carlo layer until it imports them anew.

The steps are in :mod:`kalcal.filters.steps`, the square-root factors in :mod:`kalcal.filters.sqrt_form`
and the gain schedule in :mod:`kalcal.filters.gains`; new code imports from those.
"""

from __future__ import annotations

from kalcal.filters.gains import GainSchedule, covariance_pass, interval_transition, run_with_gains
from kalcal.filters.steps import UpdateForm

__all__ = ["GainSchedule", "UpdateForm", "covariance_pass", "interval_transition", "run_with_gains"]
