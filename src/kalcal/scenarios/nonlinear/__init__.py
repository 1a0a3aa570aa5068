"""The nonlinear scenario: a model written as code (a Python file or a :class:`kalcal.NonlinearModel`), its
EKF, iterated EKF or UKF verified by Monte Carlo with effect sizes and the Cramér–Rao bound."""
