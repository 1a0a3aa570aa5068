"""A calibration's diagnostics and warnings are the typed objects the calibration made; ``to_dict()``
gives summary.json's keys unchanged."""

from __future__ import annotations

import dataclasses

import kalcal
from kalcal.calibration.plausibility import CalibrationWarning
from kalcal.calibration.warnings import untrusted_warning
from kalcal.scenarios.scale_bias.job import ScaleBiasDiagnostics


def test_scale_bias_diagnostics_are_typed_and_summary_json_keeps_its_keys(tmp_path):
    sim = kalcal.simulate("scale-bias", seed=1)
    result = kalcal.calibrate("scale-bias", data=sim.logs["data"])
    diagnostics = result.diagnostics
    assert isinstance(diagnostics, ScaleBiasDiagnostics) and dataclasses.is_dataclass(diagnostics)
    low, high = diagnostics.nis_bounds
    assert diagnostics.consistent == (low <= diagnostics.mean_nis <= high)
    assert ("within" if diagnostics.consistent else "outside") in diagnostics.verdict
    summary = result.to_dict()
    assert set(diagnostics.to_dict()) == {"mean_nis", "nis_bounds", "consistent", "observability"}
    assert (summary["mean_nis"], summary["nis_bounds"], summary["consistent"]) == (diagnostics.mean_nis, list(diagnostics.nis_bounds), diagnostics.consistent)
    assert summary["observability"]["unobservable"] == diagnostics.observability["unobservable"]
    assert all(isinstance(w, CalibrationWarning) for w in result.warnings)
    assert summary["warnings"] == [{"code": w.code, "message": w.message} for w in result.warnings]


def test_the_untrusted_warning_names_its_next_step_but_writes_code_and_message_only():
    fit = "kalcal fit accel-gps --imu imu.csv --gps gps.csv --out fit"
    because, warning = untrusted_warning({"consistent": False, "verdict": "mean NIS too large"}, {"stable": True},
                                         0.01, "m/s^2", fit)
    assert warning.code == "sigma-untrusted" and warning.next_step == fit and fit in warning.message
    assert warning.to_dict() == {"code": "sigma-untrusted", "message": warning.message}
    assert "inconsistent" in because
