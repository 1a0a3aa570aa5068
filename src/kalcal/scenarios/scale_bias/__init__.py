"""The scale-bias scenario: a sensor's scale and bias from known inputs, its settings, simulation, calibration and fit."""
