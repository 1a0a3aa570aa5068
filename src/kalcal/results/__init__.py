"""The results of ``calibrate``, ``verify``, ``simulate`` and ``noise``: each the object its command made, with ``to_dict()`` and ``save(out)``.

A scenario's calibration extends :class:`~kalcal.results.calibration.CalibrationResult` with its own fields,
in its package (``kalcal.scenarios.accel_gps.calibrate``, ``kalcal.scenarios.scale_bias.job``); a fit's
result is :class:`kalcal.fitting.result.FitResult`.
"""
