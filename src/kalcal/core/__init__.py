"""The scenario-free Kalman algebra: for now its one compiled covariance update (:mod:`kalcal.core.kernels`).

core will hold the model containers, the numpy reference of every step (predict; update in Joseph,
standard and square-root form; a missing measurement as a prediction only), the covariance pass, the
RTS smoother, the prediction-error likelihood and the exact covariance analysis. Nothing in it names a
scenario.
"""
