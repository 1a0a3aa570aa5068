"""The figure functions the jobs call through :mod:`kalcal.reporting.figure_process`, by name.

Each is ``"module:function"``: the figure process imports the modules while the job computes, and runs
the function when the job calls it (in the job's own process where there is no figure process).
"""

from __future__ import annotations

__all__ = ["ANALYSIS_FIGURES", "CALIBRATION_FIGURE", "FIT_FIGURE", "NOISE_FIGURE", "REPORT_FIGURES",
           "REPORT_REALIZATION_FIGURES", "REPORT_STATISTICS_FIGURES", "SWEEP_FIGURE"]  # fmt: skip

#: a verification's page: all of its figures where they are drawn in the job's process; in the figure
#: process in two parts, the statistics' drawn while the job simulates the realization shown, then the
#: realization's
REPORT_FIGURES = "kalcal.reporting.figures:render_figures"
REPORT_STATISTICS_FIGURES = "kalcal.reporting.figures:render_statistics_figures"
REPORT_REALIZATION_FIGURES = "kalcal.reporting.figures:render_realization_figures"
#: ``kalcal calibrate accel-gps``'s calibration.png
CALIBRATION_FIGURE = "kalcal.plots.calibration:plot_calibration"
#: ``kalcal fit``'s fit.png
FIT_FIGURE = "kalcal.plots.fit:plot_fit"
#: ``kalcal noise``'s allan.png
NOISE_FIGURE = "kalcal.plots.allan:plot_allan"
#: ``kalcal analyze``'s two figures
ANALYSIS_FIGURES = "kalcal.plots.analysis:plot_analysis"
#: ``kalcal sweep``'s sweep.png
SWEEP_FIGURE = "kalcal.plots.sweep:plot_sweep"
