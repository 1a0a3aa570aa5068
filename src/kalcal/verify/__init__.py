"""Statistical checks of a filter against its Monte Carlo ensemble.

- :mod:`kalcal.verify.checks`: the five checks, run in order, and the verdict.
- :mod:`kalcal.verify.covariance`: the covariance check and the cause of its failure.
- :mod:`kalcal.verify.whiteness`: the residual whiteness check (pairs and portmanteau).
- :mod:`kalcal.verify.bounds`: the bounds of the checks' families and the verdict's false-alarm bound.
- :mod:`kalcal.verify.check_steps`: the steps the checks share (z-statistics, detail text, results).
- :mod:`kalcal.verify.results`: result objects and p-values; :mod:`kalcal.verify.text`: their words.
"""
