"""Matplotlib figures: one function per figure, presentation only.

Each function takes data that is already computed (a ``stats.nc`` Dataset, or one realization as
:class:`~kalcal.plots.realization.RealizationData`) and a path, and writes a PNG of a fixed pixel size
(900 px wide; see each docstring for the height) whose bytes depend only on the data.

- :mod:`kalcal.plots.realization`: one realization, true and estimated states, errors with +-1 sigma
  (source report figures 5.1-5.6).
- :mod:`kalcal.plots.ensemble`: ensemble mean error, covariance and orthogonality with their bands (5.7-5.12),
  and the filter, exact and ensemble sigma per state.
- :mod:`kalcal.plots.consistency`: mean NEES and NIS, the residual-correlation map, the model-error response.
- :mod:`kalcal.plots.calibration`: a calibrated log's bias and normalized innovations.
- :mod:`kalcal.plots.fit`: log-likelihood along each fitted noise setting, its interval marked.
- :mod:`kalcal.plots.sweep`: each check's statistic against a swept setting (the tuning curve).

Only this package imports matplotlib; it uses the Agg canvas directly and never pyplot.
"""
