"""Statistical checks of a filter against its Monte Carlo ensemble.

- :mod:`kalcal.stats.checks`: the five checks, run in order, and the verdict.
- :mod:`kalcal.stats.covariance`: the covariance check and the cause of its failure.
- :mod:`kalcal.stats.whiteness`: the residual whiteness check (pairs and portmanteau).
- :mod:`kalcal.stats.bounds`: the bounds of the checks' families and the verdict's false-alarm bound.
- :mod:`kalcal.stats.check_steps`: the steps the checks share (z-statistics, detail text, results).
- :mod:`kalcal.stats.results`: result objects and p-values; :mod:`kalcal.stats.text`: their words.
"""
