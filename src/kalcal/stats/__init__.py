"""Statistical checks of a filter against its Monte Carlo ensemble, one module per check with its bounds and power.

- :mod:`kalcal.stats.suite`: the six checks run in order, the verdict, and their power rows.
- :mod:`kalcal.stats.mean_error`, :mod:`kalcal.stats.covariance`, :mod:`kalcal.stats.orthogonality`,
  :mod:`kalcal.stats.whiteness`, :mod:`kalcal.stats.nis`: each check, its statistic and its power side by
  side (the NIS module also holds the innovation gate's excess rule).
- :mod:`kalcal.stats.bounds`: the bounds of the checks' families and the verdict's false-alarm bound.
- :mod:`kalcal.stats.power`: the power families the checks' own power functions build.
- :mod:`kalcal.stats.results`: result objects, p-values and the steps that build a result (z-statistics,
  detail text, causes); :mod:`kalcal.stats.text`: their words.
"""
