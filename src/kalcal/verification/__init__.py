"""Statistical checks of a filter against its Monte Carlo ensemble.

- :mod:`kalcal.verification.checks`: the five checks, run in order, and the verdict.
- :mod:`kalcal.verification.covariance`: the covariance check and the cause of its failure.
- :mod:`kalcal.verification.whiteness`: the residual whiteness check (pairs and portmanteau).
- :mod:`kalcal.verification.bounds`: the bounds of the checks' families and the verdict's false-alarm bound.
- :mod:`kalcal.verification.check_steps`: the steps the checks share (z-statistics, detail text, results).
- :mod:`kalcal.verification.results`: result objects and p-values; :mod:`kalcal.verification.text`: their words.
"""
