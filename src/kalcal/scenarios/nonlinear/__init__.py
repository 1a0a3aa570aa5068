"""The nonlinear scenario: a model written as code, its EKF, IEKF or UKF verified by Monte Carlo.

The model is a Python file or a :class:`kalcal.NonlinearModel`; the checks carry effect sizes and the
Cramér–Rao bound."""
