"""Exact covariance analysis of fixed-gain filters: every moment the Monte Carlo estimates, without sampling."""
