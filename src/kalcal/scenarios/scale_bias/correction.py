"""The correction a scale-bias calibration gives: a sensor reading z put on the reference's scale, with its sigma.

The filter's model is reference_k = theta1 z_k + theta2 + w_k, w_k ~ N(0, R) (settings' docstring), so a
reading z of the calibrated sensor maps to c(z) = theta1 z + theta2 in the reference's (the signal's) unit.
With theta's estimate at the last sample and its covariance P (2 x 2), h = [z, 1]:

* ``line``: var c(z) = h P h^T, the error of the estimated map itself at z (what every corrected reading
  at z shares, and all that averaging many readings at z leaves);
* ``prediction``: h P h^T + R, the spread of a new reference reading about c(z) (R the filter's
  measurement noise variance, sigma_eta^2 + theta1^2 sigma_nu^2 with noise_model "exact": the reference's
  own noise and the sensor's, through theta1).

The quantity psi itself (the reference without its noise) lies about c(z) with h P h^T + theta1^2
sigma_nu^2, between the two: ``sensor_noise_variance`` holds that term. With a drifting theta
(``filter.parameter_drift_std`` > 0) a reading ``n`` samples after the log's last adds n Q to P.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np

#: the map the correction applies, in words (correction.json's ``model``)
MODEL = "reference = theta1 * sensor + theta2"
#: the two standard errors, as correction.json states them
STANDARD_ERRORS = {
    "line": "sqrt([z, 1] P [z, 1]^T): the estimated map's own error at the reading z",
    "prediction": "sqrt([z, 1] P [z, 1]^T + measurement_noise_variance): a new reference reading at z",
}


class Corrected(NamedTuple):
    """A corrected reading and its 1-sigma, in the signal's unit, of the shape of the readings."""

    value: np.ndarray | float
    sigma: np.ndarray | float


@dataclass(frozen=True, eq=False)
class ScaleBiasCorrection:
    """reference = theta1 * sensor + theta2, estimated at the log's last sample (``correction.json``).

    Attributes
    ----------
    theta : ndarray, shape (2,)
        [theta1 (1), theta2 (signal unit)] at the last sample.
    covariance : ndarray, shape (2, 2)
        P of theta at the last sample (units [1, unit; unit, unit^2]).
    measurement_noise_variance : float
        R, the filter's variance of w_k, unit^2.
    sensor_noise_variance : float
        The sensor's part of R, gain^2 sigma_nu^2 (gain: theta1 at the filter's prior mean, or 1 with
        ``noise_model = "note"``), unit^2.
    process_noise : ndarray, shape (2, 2)
        Q per sample, added n times for a reading n samples after the last.
    time : float
        s, the last sample's time: the time the estimate refers to.
    unit : str
        The signal's unit (reading and corrected value).
    sigma_trusted : bool
        The calibration's verdict on its sigmas: False where the diagnostics or the windows disown them
        (``sigma_untrusted_because`` says why); the sigmas of :meth:`apply` are then not to be used.
    sigma_untrusted_because : str or None
    data : str
        The log the estimate was made from.
    columns : dict
        The log's ``reference`` and ``sensor`` columns.
    """

    theta: np.ndarray
    covariance: np.ndarray
    measurement_noise_variance: float
    sensor_noise_variance: float
    process_noise: np.ndarray
    time: float
    unit: str
    sigma_trusted: bool
    sigma_untrusted_because: str | None = None
    data: str = "data"
    columns: dict | None = None

    def apply(self, z, prediction: bool = False, samples_after: int = 0) -> Corrected:
        """The corrected value theta1 z + theta2 and its 1-sigma at each reading.

        Parameters
        ----------
        z : float or array_like, shape (...)
            Sensor readings, signal unit.
        prediction : bool
            False: the map's own sigma, sqrt(h P h^T) with h = [z, 1]; True: a new reference reading's,
            sqrt(h P h^T + R) (module docstring).
        samples_after : int
            Samples between the log's last and the reading: P + samples_after Q (0: the log's last sample;
            no change where Q = 0).

        Returns
        -------
        Corrected
            ``value`` and ``sigma``, signal unit, of z's shape (floats for a float z).

        Warns
        -----
        UserWarning
            When the calibration does not trust its sigma (:attr:`sigma_trusted` False).
        """
        if not self.sigma_trusted:
            warnings.warn(f"apply: the calibration's sigma is not trusted ({self.sigma_untrusted_because}): the "
                          "corrected value's sigma is not to be used", stacklevel=2)
        if samples_after < 0 or int(samples_after) != samples_after:
            raise ValueError(f"samples_after: expected a whole number >= 0, got {samples_after!r}")
        z = np.asarray(z, dtype=float)
        cov = self.covariance + samples_after * self.process_noise
        value = self.theta[0] * z + self.theta[1]
        # h P h^T written out for h = [z, 1]: one expression for any shape of z
        variance = cov[0, 0] * z**2 + 2.0 * cov[0, 1] * z + cov[1, 1]
        if prediction:
            variance = variance + self.measurement_noise_variance
        sigma = np.sqrt(variance)
        if z.ndim == 0:
            return Corrected(float(value), float(sigma))
        return Corrected(value, sigma)

    def to_dict(self) -> dict[str, Any]:
        """``correction.json`` as ``json.load`` reads it."""
        from kalcal.io.results import json_document

        return json_document(self._document())

    def save(self, path: str | Path) -> Path:
        """Write ``correction.json`` to ``path`` (a file; :meth:`ScaleBiasCalibrationResult.save` writes it
        with the rest of the set)."""
        from kalcal.io.results import write_json

        return write_json(path, self._document())

    def _document(self) -> dict[str, Any]:
        unit = self.unit
        return {
            "scenario": "scale-bias",
            "model": MODEL,
            "data": self.data,
            "columns": dict(self.columns or {}),
            "time": self.time,
            "theta": self.theta,
            "theta_states": ["theta1", "theta2"],
            "theta_covariance": self.covariance,
            "measurement_noise_variance": self.measurement_noise_variance,
            "sensor_noise_variance": self.sensor_noise_variance,
            "process_noise_per_sample": self.process_noise,
            "standard_error": dict(STANDARD_ERRORS),
            "sigma_trusted": self.sigma_trusted,
            **({"sigma_untrusted_because": self.sigma_untrusted_because} if not self.sigma_trusted else {}),
            "units": {"sensor": unit, "corrected": unit, "theta1": "1", "theta2": unit, "time": "s",
                      "theta_covariance": f"[[1, {unit}], [{unit}, ({unit})^2]]",
                      "process_noise_per_sample": f"[[1, {unit}], [{unit}, ({unit})^2]]",
                      "measurement_noise_variance": f"({unit})^2", "sensor_noise_variance": f"({unit})^2"},
        }

    def __repr__(self) -> str:
        trust = "" if self.sigma_trusted else ", sigma NOT trusted"
        sign = "-" if self.theta[1] < 0 else "+"
        return (f"ScaleBiasCorrection(reference = {self.theta[0]:.6g} * sensor {sign} {abs(self.theta[1]):.6g} [{self.unit}], "
                f"t = {self.time:g} s{trust})")
