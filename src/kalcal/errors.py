"""The package's error types.

Every error a user can cause is a :class:`KalcalError` (a ``ValueError``) whose message names the file,
row, column or setting and the offending value; the CLI prints it as one line and exits with status 2.
"""


class KalcalError(ValueError):
    """Base class of every user-facing error."""


class ConfigError(KalcalError):
    """A setting or an option is unknown, malformed or out of range.

    A scenario's or a model file's setting raises the subclass
    :class:`kalcal.models.settings.SettingError`, worded ``FILE: KEY: expected ..., got ...``.
    """


class DataError(KalcalError):
    """A log file cannot be used: missing, empty, malformed or physically inconsistent."""
