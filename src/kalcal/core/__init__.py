"""The scenario-free Kalman algebra: what a linear Gaussian model is, and the one algebra over it.

- :mod:`kalcal.core.model`: :class:`~kalcal.core.model.LinearGaussianModel`, the immutable model container.
- :mod:`kalcal.core.steps`: the numpy reference of every step (predict; the Joseph and standard updates; the NIS;
  the interval transition; the covariance pass).
- :mod:`kalcal.core.sqrt_form`: the square-root predict and update and their factor algebra.
- :mod:`kalcal.core.diffuse`: the information filter's start for a diffuse state (numpy; compiled in kernels).
- :mod:`kalcal.core.missing`: a missing measurement is a prediction only, one wrapper for every form.
- :mod:`kalcal.core.smoother`: the RTS smoother over a filter's run.
- :mod:`kalcal.core.likelihood`: the prediction-error decomposition of a filter's innovations.
- :mod:`kalcal.core.timevarying`: :class:`~kalcal.core.timevarying.TimeVaryingModel`, a model whose rows, noise
  and inputs change per step (a model with data).
- :mod:`kalcal.core.timevarying_filter`: its filter (:func:`~kalcal.core.timevarying_filter.filter_model`, a
  :class:`~kalcal.core.timevarying_filter.TimeVaryingRun`; the numpy
  :func:`~kalcal.core.timevarying_filter.reference_filter`), the exact diffuse initialization, the conditional
  log-likelihood (:func:`~kalcal.core.timevarying_filter.loglik`, compiled) and the RTS smoother over it
  (:func:`~kalcal.core.timevarying_filter.smooth`); :mod:`kalcal.core.timevarying_kernels` is its compiled
  part.
- :mod:`kalcal.core.lincov`: the exact moments of a fixed-gain filter against its linear truth.
- :mod:`kalcal.core.sources`, :mod:`kalcal.core.budget`: the truth's independent noise sources, and the
  error budget, each source's exact share of the true error covariance.
- :mod:`kalcal.core.kernels`: the one compiled covariance update that every compiled path calls, and the
  diffuse start's compiled twin.

Nothing in it names a scenario (tests/core/test_scenario_free.py).
"""
