"""A model file over one log as a verification scenario: ``verify`` and ``analyze`` with ``--data LOG``.

:class:`LoggedModelScenario` is the file's :class:`~kalcal.scenarios.model_file.model.CustomModelScenario`
with the log it runs over (settings section ``log``: the path and SHA-256 of the log, so that ``kalcal
report DIR`` reads the same bytes again, or refuses in one line where the log has moved or changed). Its
problem is :class:`~kalcal.scenarios.model_file.logged.LoggedGainProblem` (the gains from the log's rows,
once); the mathematics and its limits are in :mod:`kalcal.scenarios.model_file.logged`.
"""

from __future__ import annotations

import dataclasses
import functools
from dataclasses import dataclass
from pathlib import Path
from typing import Any, ClassVar

import numpy as np

from kalcal.scenarios.model_file.logged import LogRecord, check_record, record_log
from kalcal.scenarios.model_file.model import CustomModelScenario
from kalcal.scenarios.protocol import Capabilities

@dataclass(frozen=True)
class LoggedModelScenario(CustomModelScenario):
    """A model file bound to a log for ``verify`` and ``analyze`` (the file's [data] table names the columns).

    Attributes
    ----------
    log : LogRecord
        The log's path (resolved), SHA-256 and topic.
    """

    NAME: ClassVar[str] = "custom"

    log: LogRecord | None = None

    def __post_init__(self) -> None:
        super().__post_init__()
        if self.log is None:
            raise ValueError("a model file over a log needs the log")
        if not isinstance(self.log, LogRecord):
            object.__setattr__(self, "log", LogRecord(**self.log))

    @functools.cached_property
    def bound(self):
        """The file bound to the log (:func:`kalcal.scenarios.model_file.data.bind`)."""
        from kalcal.scenarios.model_file.data import bind

        return bind(self, self.log.path, topic=self.log.topic or None)

    @functools.cached_property
    def arrays(self):
        """The verification's per-update arrays (:func:`kalcal.scenarios.model_file.logged.logged_arrays`)."""
        from kalcal.scenarios.model_file.logged import logged_arrays

        return logged_arrays(self, self.bound)

    @property
    def label(self) -> str:
        return f"a model file ({self.model.file}) over {self.log.path}"

    @property
    def capabilities(self) -> Capabilities:
        """The exact engine's fixed gains from the log's rows; verify, analyze, sweep (a verify per value of one
        number of the file, over the same log: :func:`kalcal.api.sweep.model_file_cells`) and report."""
        return Capabilities(
            exact_analysis=True,
            fixed_gains=True,
            engines=("exact",),
            long_run=False,
            commands=frozenset({"verify", "analyze", "sweep", "report"}),
            why_not=(
                ("--engine", "use the exact engine"),
                ("--long-run", "the log sets the run's length"),
                ("fit", "fit takes the log as --data without verify's binding (kalcal fit MODEL.toml --data LOG)"),
            ),
        )

    def without_log(self) -> str:
        return ""

    def problem(self, form="joseph", residual_pairs: bool = True):
        """The gains from the log's rows against the truth over them."""
        from kalcal.scenarios.model_file.logged import logged_problem

        return logged_problem(self, form, residual_pairs)

    def error_sources(self) -> list:
        from kalcal.scenarios.model_file.logged import logged_sources

        return logged_sources(self)

    def run_length(self) -> tuple[int, float]:
        """The log's update rows and the last one's time (s) after row 0."""
        times = self.arrays.times
        return int(times.size), float(times[-1] - self.bound.times[0]) if times.size else 0.0

    @property
    def update_times(self) -> np.ndarray:
        """The log's time of each update row, s, (K,)."""
        return self.arrays.times

    @classmethod
    def from_settings(cls, settings) -> LoggedModelScenario:
        """Rebuild from a summary's settings (model, filter, truth, data, log), the log read again from its
        recorded path once its digest is checked."""
        base = CustomModelScenario.from_settings({k: v for k, v in settings.items() if k != "log"})
        record = LogRecord(**settings["log"])
        check_record(record)
        return over_log(base, record)


def over_log(scenario: CustomModelScenario, log: str | Path | LogRecord, topic: str | None = None) -> LoggedModelScenario:
    """``scenario`` (a model file with a [data] table) over ``log``: refused in one line where the file
    has no [data] table, and bound at once, so that a log the file cannot take is refused before a run."""
    from kalcal.models.settings import SettingError

    if scenario.data is None:
        raise SettingError("data", "a [data] table naming the log's columns (verify --data LOG binds the file to a log)", "none", scenario.model.file)
    record = log if isinstance(log, LogRecord) else record_log(log, topic)
    fields = {f.name: getattr(scenario, f.name) for f in dataclasses.fields(CustomModelScenario)}
    built = LoggedModelScenario(**fields, log=record)
    built.arrays  # bind now: the log's faults and the stated limits are refused before anything runs
    from kalcal.io.outputs import inputs_of, mark_inputs

    return mark_inputs(built, *inputs_of(scenario), record.path)


def settings_have_log(settings: Any) -> bool:
    """Whether a summary's settings are those of a model file over a log."""
    return "log" in settings and set(settings) - {"log"} in ({"model", "filter", "truth", "data"},)
