"""The 3-axis accelerometer from static poses: scale factors, misalignment and biases, with intervals.

Procedure (a): six known faces; procedure (b): unknown poses by maximum likelihood (docs/imu-3axis.md)."""
