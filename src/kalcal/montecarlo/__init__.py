"""The batched Monte Carlo engine and its streaming statistics."""
