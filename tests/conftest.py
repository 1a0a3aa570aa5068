"""The test session's process loads matplotlib before any test: its jobs then draw their figures in it,
whatever tests ran first (:mod:`kalcal.reporting.figure_process` starts a figure process only where
matplotlib is not loaded yet). The figure process itself is tested in tests/reporting/test_figure_process.py,
and by the command-line tests that run ``kalcal`` as a child process."""

import matplotlib  # noqa: F401
