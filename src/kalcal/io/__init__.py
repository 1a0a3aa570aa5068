"""Readers of sensor logs and writers of results."""
