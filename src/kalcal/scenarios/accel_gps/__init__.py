"""The accel-gps scenario: an accelerometer and GPS fixes, its settings, truth, simulation, calibration and fit."""
