"""kalcal: Kalman-filter sensor calibration with Monte Carlo verification.

The Python API (each loaded on first use, so that ``import kalcal`` stays cheap)::

    import kalcal
    result = kalcal.verify("accel-gps", n=2000)      # VerificationResult
    kalcal.calibrate("accel-gps", imu=df, gps=df2)     # CalibrationResult
    kalcal.noise(imu=df)                               # NoiseResult
"""

import sys
import types
from importlib import import_module
from importlib.metadata import PackageNotFoundError, version

try:
    __version__ = version("kalcal")
except PackageNotFoundError:  # running from a source tree without installation
    __version__ = "0.0.0"

#: every export, by the module it comes from (PEP 562: loaded when first asked for)
_EXPORTS = {
    "verify": "kalcal.api.verify",
    "calibrate": "kalcal.api.calibrate",
    "noise": "kalcal.api.noise",
    "simulate": "kalcal.api.simulate",
    "sweep": "kalcal.api.sweep",
    "analyze": "kalcal.api.analyze",
    "AnalysisResult": "kalcal.api.analyze",
    "Model": "kalcal.api.model",
    "load_model": "kalcal.api.model",
    "VerificationResult": "kalcal.api.results",
    "CalibrationResult": "kalcal.api.results",
    "NoiseResult": "kalcal.api.results",
    "SimulationResult": "kalcal.api.results",
    "KalcalError": "kalcal.errors",
}

__all__ = ["__version__", *_EXPORTS]


def __getattr__(name: str):
    module = _EXPORTS.get(name)
    if module is None:
        raise AttributeError(f"module 'kalcal' has no attribute {name!r}")
    value = getattr(import_module(module), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted({*globals(), *_EXPORTS})


class _Package(types.ModuleType):
    """The package module: ``kalcal.verify`` and ``kalcal.calibrate`` are the calls, though subpackages of
    those names exist (``kalcal.verify.checks``): importing a subpackage does not rebind the call's name."""

    def __setattr__(self, name: str, value) -> None:
        if name in _EXPORTS and isinstance(value, types.ModuleType):
            return  # the subpackage stays importable (sys.modules); the attribute stays the call
        super().__setattr__(name, value)


sys.modules[__name__].__class__ = _Package
