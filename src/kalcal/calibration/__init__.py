"""Run a filter over logged data and return estimates with their uncertainty."""
