"""The Python API: one module per call (verify, calibrate, noise), the model builder and the result objects."""
