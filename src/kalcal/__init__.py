"""kalcal: Kalman-filter sensor calibration with Monte Carlo verification.

The Python API (each loaded on first use, so that ``import kalcal`` stays cheap)::

    import kalcal
    result = kalcal.verify("accel-gps", n=2000)      # VerificationResult
    kalcal.calibrate("accel-gps", imu=df, gps=df2)     # CalibrationResult
    kalcal.noise(imu=df)                               # NoiseResult
    kalcal.fit("accel-gps", imu=df, gps=df2)           # FitResult
"""

from importlib import import_module as _import_module

from kalcal._version import __version__

#: every export, by the module it comes from (PEP 562: loaded when first asked for)
_EXPORTS = {
    "verify": "kalcal.api.verify",
    "calibrate": "kalcal.api.calibrate",
    "fit": "kalcal.api.fit",
    "noise": "kalcal.api.noise",
    "simulate": "kalcal.api.simulate",
    "sweep": "kalcal.api.sweep",
    "analyze": "kalcal.api.analyze",
    "AnalysisResult": "kalcal.api.analyze",
    "report": "kalcal.api.report",
    "Model": "kalcal.api.model",
    "NonlinearModel": "kalcal.core.nonlinear",
    "load_model": "kalcal.api.model",
    "VerificationResult": "kalcal.results.verification",
    "CalibrationResult": "kalcal.results.calibration",
    "NoiseResult": "kalcal.results.noise",
    "SimulationResult": "kalcal.results.simulation",
    "SweepResult": "kalcal.api.sweep",
    "FitResult": "kalcal.fitting.result",
    "CheckResult": "kalcal.stats.results",
    "CheckPart": "kalcal.stats.results",
    "Cause": "kalcal.stats.results",
    "KalcalError": "kalcal.errors",
}

__all__ = ["__version__", *_EXPORTS]


def __getattr__(name: str):
    module = _EXPORTS.get(name)
    if module is None:
        raise AttributeError(f"module 'kalcal' has no attribute {name!r}")
    value = getattr(_import_module(module), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted({*__all__, *(name for name in globals() if name.startswith("__") and name.endswith("__"))})
