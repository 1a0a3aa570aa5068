"""What ``kalcal noise`` made: N, B and K of a static accelerometer log, its Allan curve and ``[filter]`` settings."""

from __future__ import annotations

import html
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:  # annotations only
    import pandas as pd


@dataclass(frozen=True, repr=False, eq=False)
class NoiseResult:
    """What :func:`kalcal.noise` identified from a static accelerometer log.

    Attributes
    ----------
    velocity_random_walk, bias_instability, rate_random_walk, accel_noise_std, bias_walk_std : NoiseParameter
        N (m/s/sqrt(s)), B (m/s^2), K (m/s^2/sqrt(s)) and the per-sample values N sqrt(rate) and
        K sqrt(dt) (m/s^2), each with ``value`` (None where not identified), ``ci_low``, ``ci_high``,
        ``upper_bound`` and ``note`` (:class:`kalcal.calibration.noise.NoiseParameter`).
    rate : float
        The log's median sample rate (Hz).
    filter : dict
        The ``[filter]`` settings of ``filter.toml``: the rate-free densities accel_noise_density (N,
        m/s^2/sqrt(Hz)) and bias_walk_density (K, m/s^3/sqrt(Hz)) where identified.
    kalibr : dict
        The Kalibr ``imu.yaml`` values (continuous-time densities; see :mod:`kalcal.calibration.kalibr`).
    allan : pandas.DataFrame
        ``allan.csv``: tau [s], adev and its bounds [m/s^2], edf, noise type.
    warnings : list of dict
        ``{"code", "message"}`` each (a log that does not look static), empty when none.
    identification : NoiseIdentification or None
        N, B, K and the per-sample values with their intervals, and the Allan curve: of the log's one
        column, or of the axis ``axis=`` selects in a three-axis log (None when none is selected).
    raw_summary : dict
        ``summary.json``'s content but its ``files`` (which only a save knows).
    filter_text : str or None
        ``filter.toml`` (None, and no filter.toml, for a three-axis log without a selected axis).
    title : str
        The Allan plot's title.
    topic : str or None
        The Kalibr ``rostopic`` (the bag's topic), None for the default.
    paths : dict
        The files written (by key) when the call was given ``out``; empty otherwise.
    axes : dict
        A three-axis log's (a bag's or ULog's accelerometer) ``{"x": NoiseIdentification, "y": ..., "z":
        ...}``, empty for one column. The parameters above are then the selected axis's (``axis=``), None
        without one, and ``kalibr`` holds the largest densities over the axes.
    """

    identification: Any = field(repr=False)
    raw_summary: dict = field(repr=False)
    filter_text: str | None = field(repr=False)
    allan: pd.DataFrame = field(repr=False)
    title: str = field(repr=False)
    axes: dict = field(default_factory=dict, repr=False)
    topic: str | None = field(default=None, repr=False)
    paths: dict = field(default_factory=dict)

    def _parameter(self, name: str):
        return None if self.identification is None else getattr(self.identification, name)

    @property
    def velocity_random_walk(self):
        """N, m/s/sqrt(s) (:class:`~kalcal.calibration.noise.NoiseParameter`; None without a selected axis)."""
        return self._parameter("velocity_random_walk")

    @property
    def bias_instability(self):
        """B, m/s^2."""
        return self._parameter("bias_instability")

    @property
    def rate_random_walk(self):
        """K, m/s^2/sqrt(s)."""
        return self._parameter("rate_random_walk")

    @property
    def accel_noise_std(self):
        """N sqrt(rate), the white noise's std per sample at the log's rate, m/s^2."""
        return self._parameter("accel_noise_std")

    @property
    def bias_walk_std(self):
        """K sqrt(dt), the bias walk's step per sample at the log's rate, m/s^2."""
        return self._parameter("bias_walk_std")

    @property
    def rate(self) -> float:
        """The log's median sample rate, Hz."""
        return float(self.raw_summary["rate"]["value"])

    @property
    def filter(self) -> dict:
        """``filter.toml``'s ``[filter]`` settings (``summary.json``'s ``filter``)."""
        return dict(self.raw_summary["filter"])

    @property
    def kalibr(self) -> dict:
        """The Kalibr ``imu.yaml`` values (the largest densities over the axes of a three-axis log)."""
        from kalcal.calibration.kalibr import axes_kalibr_values, kalibr_values

        rostopic = self.topic or "/imu0"
        return axes_kalibr_values(self.axes, rostopic) if self.axes else kalibr_values(self.identification, rostopic)

    @property
    def warnings(self) -> list:
        """``summary.json``'s ``warnings``: ``{"code", "message"}`` each."""
        return list(self.raw_summary["warnings"])

    #: the parameters :meth:`conf_int` gives, in its rows' order
    PARAMETERS = ("velocity_random_walk", "bias_instability", "rate_random_walk", "accel_noise_std", "bias_walk_std")

    @property
    def confidence(self) -> float | None:
        """The two-sided level of every stored interval (None without a selected axis)."""
        return None if self.identification is None else float(self.velocity_random_walk.confidence)

    def conf_int(self, level: float | None = None) -> pd.DataFrame:
        """The Allan parameters' intervals, one row per parameter (:data:`PARAMETERS`), columns ``lower``,
        ``upper`` (NaN where the curve does not show the parameter: its ``upper_bound`` in the summary
        bounds it instead) and ``unit``.

        ``level`` defaults to the stored one (``confidence`` of :func:`kalcal.noise`). The intervals are read
        off the Allan curve's own chi-square bounds at that level, through the regions chosen at it, so
        another level is refused (ValueError) rather than rescaled: identify again with
        ``kalcal.noise(..., confidence=level)``.
        """
        import pandas as pd

        if self.identification is None:
            raise ValueError("conf_int: a three-axis log with no selected axis has no intervals (give axis=)")
        stored = self.confidence
        if level is not None and abs(level - stored) > 1e-12:
            raise ValueError(f"conf_int: level {level!r}: the intervals were computed at {stored:g}; identify again "
                             f"with confidence={level!r} for that level")
        nan = float("nan")
        rows = {name: (nan if p.low is None else p.low, nan if p.high is None else p.high, p.unit)
                for name in self.PARAMETERS for p in [getattr(self, name)]}
        return pd.DataFrame.from_dict(rows, orient="index", columns=["lower", "upper", "unit"])

    def to_dict(self) -> dict[str, Any]:
        """``summary.json`` as ``json.load`` reads it, but for ``files`` (which only a save knows)."""
        from kalcal.io.results import json_document

        return json_document(self.raw_summary)

    def save(self, out: str | Path, *, kalibr: bool = True) -> dict[str, str]:
        """Write ``summary.json``, ``allan.csv``, ``allan.png``, ``filter.toml`` and (unless ``kalibr`` is
        False) the Kalibr ``imu.yaml`` into ``out``, as ``kalcal noise --out`` does (one set); returns the
        files by key (summary, allan, plot, filter, kalibr)."""
        from kalcal.calibration.noise_run import save_noise

        return save_noise(self, out, kalibr=kalibr)["files"]

    def kalibr_yaml(self, rostopic: str = "/imu0") -> str:
        """The Kalibr ``imu.yaml`` text (see :mod:`kalcal.calibration.kalibr`)."""
        from kalcal.calibration.kalibr import kalibr_yaml

        return kalibr_yaml(self.identification, rostopic=rostopic)

    def _repr_html_(self) -> str:
        from kalcal.results._display import html_facts, html_table

        names = ("velocity_random_walk", "bias_instability", "rate_random_walk", "accel_noise_std", "bias_walk_std")
        rows = []
        for name in names:
            p = getattr(self, name)
            rows.append([name, p.value, p.low, p.high, p.upper_bound, p.unit, p.note])
        confidence = self.velocity_random_walk.confidence
        facts = html_facts("kalcal noise", [("rate, Hz", self.rate), ("confidence", confidence), ("warnings", len(self.warnings))])
        table = html_table(["parameter", "value", "lower", "upper", "upper bound", "unit", "note"], rows)
        notes = "".join(f"<li>{html.escape(str(w.get('code', '')))}: {html.escape(str(w.get('message', '')))}</li>"
                        for w in self.warnings)
        return f"<div>{facts}{table}" + (f"<ul>{notes}</ul>" if notes else "") + "</div>"

    def __repr__(self) -> str:
        def show(p) -> str:
            return "not identified" if p.value is None else f"{p.value:.4g} {p.unit}"

        return (
            f"NoiseResult(N={show(self.velocity_random_walk)}, B={show(self.bias_instability)}, "
            f"K={show(self.rate_random_walk)}, rate={self.rate:.6g} Hz)"
        )
