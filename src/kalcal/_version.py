"""kalcal's version, written here alone.

``pyproject.toml`` reads it for the package's metadata (setuptools' ``attr``, from the source without
importing it), and ``kalcal.__version__`` is this, not a lookup in the installed packages' metadata (a few
ms in a job, where numba and numpy.testing have loaded importlib.metadata already; 40-45 ms where
``import kalcal`` is all that ran).
"""

__version__ = "0.1.0"
