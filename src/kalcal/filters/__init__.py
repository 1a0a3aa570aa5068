"""Scenario-free filters on core's steps, batched over realizations: gain schedules, the regression filter, the log filter, the steady state."""
