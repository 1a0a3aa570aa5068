"""Statistical checks of a filter against its Monte Carlo ensemble."""
