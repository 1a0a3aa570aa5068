"""What every scenario's log calibration shares: innovation diagnostics, windowed stability, plausibility, unit slips, noise from a static log."""
