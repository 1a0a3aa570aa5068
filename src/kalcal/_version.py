"""kalcal's version, written here alone: ``pyproject.toml`` reads it for the package's metadata
(setuptools' ``attr``, from the source without importing it), and ``kalcal.__version__`` is this, so
that no job reads the installed package's metadata (importlib.metadata: 40-45 ms of every
``kalcal verify`` and ``kalcal calibrate`` on the 2-core development machine)."""

__version__ = "0.1.0"
