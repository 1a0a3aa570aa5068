"""What ``CalibrationResult.scenario`` and ``FitResult.scenario`` hold for each kind of scenario, as their
docstrings say: a built-in's name, "custom" (calibrate) or the model's own name (fit) for a model file,
and a one-line refusal where the kind has no calibration or no fit."""

from __future__ import annotations

from pathlib import Path

import pytest

import kalcal
from kalcal.errors import KalcalError
from tests.scenarios.model_file.test_calibrate_simulate import TRACKER, tracker_log

ROOT = Path(__file__).resolve().parents[2]
CODE = ROOT / "examples" / "range_bearing.py"


def test_a_model_file_calibrates_as_custom_and_fits_under_its_model_s_name(tmp_path):
    model = tmp_path / "model.toml"
    model.write_text(TRACKER)
    log = tmp_path / "log.csv"
    tracker_log().to_csv(log, index=False)
    calibration = kalcal.calibrate(str(model), data=str(log))
    assert calibration.scenario == "custom" and calibration.name == "tracker"
    assert calibration.to_dict()["scenario"] == "custom" and calibration.to_dict()["model"] == "tracker"
    fit = kalcal.fit(str(model), data=str(log))
    assert fit.scenario == "tracker" and fit.to_dict()["scenario"] == "tracker"


def test_imu_3axis_calibrates_under_its_name_and_has_no_fit():
    from tests.scenarios.test_imu_3axis import LOG, POSES

    assert kalcal.calibrate("imu-3axis", imu=LOG, poses=POSES).scenario == "imu-3axis"
    with pytest.raises(KalcalError, match="imu-3axis has no noise fit"):
        kalcal.fit("imu-3axis", imu=LOG)


@pytest.mark.parametrize("command, why", [("calibrate", "no calibration of logs"), ("fit", "no noise fit")])
def test_a_model_written_as_code_has_neither_calibration_nor_fit(command, why, tmp_path):
    log = tmp_path / "log.csv"
    log.write_text("time,x\n0,1\n")
    with pytest.raises(KalcalError, match=why):
        getattr(kalcal, command)(str(CODE), data=str(log))
