"""Pure filter functions over a model and data."""
