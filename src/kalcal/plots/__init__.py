"""Matplotlib figures: one function per figure, presentation only."""
