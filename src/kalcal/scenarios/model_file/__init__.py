"""The model-file scenario: a linear Gaussian model read from a TOML file, and its truth."""
