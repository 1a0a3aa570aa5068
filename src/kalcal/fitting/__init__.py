"""Fit a filter's noise settings to one log by maximum likelihood, with intervals and an adequacy verdict."""
