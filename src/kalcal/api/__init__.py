"""The Python API: one module per command (kalcal.verify, calibrate, fit, noise, simulate, sweep, analyze, report), the model builder and the result objects."""
