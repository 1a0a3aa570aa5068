"""Range and bearing to a beacon from a constant-velocity target: a nonlinear model file (docs/nonlinear.md).

States (4): px, py (m), vx, vy (m/s) in a plane; measurements (2): the range (m) and the bearing (rad,
counter-clockwise from the x axis) from the beacon, whose position (m) is the update's data. One
measurement a second, K = 100 updates. The track runs from (200, 100) m towards (100, 200) m, so that the
bearing stays within (-0.5, 2.5) rad (500 simulated tracks), far from the +-pi cut of arctan2: the filters subtract bearings
without wrapping them.

Read by ``kalcal.core.nonlinear.load_nonlinear_model("examples/range_bearing.py")``: it defines ``MODEL``.
"""

import numpy as np

from kalcal.core import xmath as xm
from kalcal.core.nonlinear import NonlinearModel

DT = 1.0  #: s between two measurements
N_UPDATES = 100  #: K
BEACON = np.array([0.0, 0.0])  #: the beacon's position (m), the data of every update
ACCEL_PSD = 0.01  #: white-acceleration power spectral density per axis (m^2/s^3)
RANGE_STD = 1.0  #: m
BEARING_STD = 0.01  #: rad


def f(x, u, dt):
    """Constant velocity: p += v dt, v unchanged. x (n, 4) -> (n, 4)."""
    px, py, vx, vy = x[:, 0], x[:, 1], x[:, 2], x[:, 3]
    return xm.stack([px + dt * vx, py + dt * vy, vx, vy])


def h(x, data):
    """Range (m) and bearing (rad) from the beacon at data = (bx, by) (m). x (n, 4) -> (n, 2)."""
    dx = x[:, 0] - data[..., 0]
    dy = x[:, 1] - data[..., 1]
    return xm.stack([xm.hypot(dx, dy), xm.arctan2(dy, dx)])


def process_noise(dt: float, psd: float) -> np.ndarray:
    """The discrete white-noise-acceleration covariance over dt (per axis [[dt^3/3, dt^2/2], [dt^2/2, dt]] psd)."""
    axis = psd * np.array([[dt**3 / 3.0, dt**2 / 2.0], [dt**2 / 2.0, dt]])
    q = np.zeros((4, 4))
    q[np.ix_([0, 2], [0, 2])] = axis
    q[np.ix_([1, 3], [1, 3])] = axis
    return q


MODEL = NonlinearModel(
    f=f,
    h=h,
    q=process_noise(DT, ACCEL_PSD),
    r=np.diag([RANGE_STD**2, BEARING_STD**2]),
    x0=[200.0, 100.0, -1.0, 1.0],
    p0=np.diag([25.0, 25.0, 0.25, 0.25]),
    dt=DT,
    state_names=("px", "py", "vx", "vy"),
    state_units=("m", "m", "m/s", "m/s"),
    measurement_names=("range", "bearing"),
    measurement_units=("m", "rad"),
    data_dim=2,
)

DATA = BEACON  #: the data of every update: the beacon's position (m), shared by all updates
