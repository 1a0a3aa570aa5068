"""Bad input to a nonlinear model's run, on the compiled path and the numpy path alike: one line on stderr,
exit status 2, naming the file and the field (a DATA or INPUTS of the wrong width or with fewer rows than
updates), or the function (a truth's h that is not finite at the truth's states).

The compiled path's files reuse range-bearing's printed kernel (compiled by the tests of
test_nonlinear_compiled.py, or in numba's cache), or are refused before the kernel runs."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
EXAMPLE = ROOT / "examples" / "range_bearing.py"

_WITH_INPUTS = '''
import numpy as np
from kalcal.core import xmath as xm
from kalcal.core.nonlinear import NonlinearModel
def f(x, u, dt):
    return xm.stack([x[:, 0] + dt * x[:, 2] + 0.5 * dt**2 * u[..., 0], x[:, 1] + dt * x[:, 3] + 0.5 * dt**2 * u[..., 1],
                     x[:, 2] + dt * u[..., 0], x[:, 3] + dt * u[..., 1]])
def h(x, data):
    return xm.stack([xm.hypot(x[:, 0], x[:, 1]), xm.arctan2(x[:, 1], x[:, 0])])
MODEL = NonlinearModel(f=f, h=h, q=0.01 * np.eye(4), r=np.diag([1.0, 1e-4]), x0=[200.0, 100.0, -1.0, 1.0],
                       p0=np.diag([25.0, 25.0, 0.25, 0.25]), dt=1.0, state_names=("px", "py", "vx", "vy"),
                       state_units=("m", "m", "m/s", "m/s"), measurement_names=("range", "bearing"),
                       measurement_units=("m", "rad"), input_dim=2)
N_UPDATES = 5
'''

_NAN_H = '''
import numpy as np
from kalcal.core import xmath as xm
from kalcal.core.nonlinear import NonlinearModel
MODEL = NonlinearModel(f=lambda x, u, dt: x, h=lambda x, data: xm.stack([xm.sqrt(x[:, 0] - 100.0), x[:, 1]]),
                       q=0.01 * np.eye(2), r=np.eye(2), x0=[0.0, 0.0], p0=np.eye(2), dt=1.0, state_names=("a", "b"),
                       state_units=("m", "m"), measurement_names=("p", "q"), measurement_units=("m", "m"))
N_UPDATES = 5
'''

CASES = {
    # name: (file text, what the one line must say)
    "data_width": (f"exec(open({str(EXAMPLE)!r}).read())\nimport numpy as np\nDATA = np.zeros(3)\nN_UPDATES = 5\n",
                   ("DATA", "(3,)")),
    "data_rows": (f"exec(open({str(EXAMPLE)!r}).read())\nimport numpy as np\nDATA = np.zeros((3, 2))\nN_UPDATES = 5\n",
                  ("DATA", "5 updates need 5 rows", "(3, 2)")),
    "inputs_width": (_WITH_INPUTS + "INPUTS = np.zeros(3)\n", ("INPUTS", "(3,)")),
    "inputs_rows": (_WITH_INPUTS + "INPUTS = np.zeros((2, 2))\n", ("INPUTS", "5 updates need 5 rows", "(2, 2)")),
    # the beacon at infinity: range-bearing's h infinite at every truth state (its kernel, compiled)
    "h_infinite": (f"exec(open({str(EXAMPLE)!r}).read())\nimport numpy as np\nDATA = np.array([np.inf, 0.0])\nN_UPDATES = 5\n",
                   ("the truth's h is not finite", "update 1")),
}


def _verify(path: Path, out: Path, compiled: str) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", "kalcal", "verify", str(path), "-n", "200", "--out", str(out),
         "--set", f"filter.compiled={compiled}"],
        capture_output=True, text=True,
    )


def _assert_one_line(done: subprocess.CompletedProcess, path: Path, words) -> None:
    assert done.returncode == 2, done.stderr
    lines = done.stderr.strip().splitlines()
    assert len(lines) == 1, done.stderr
    assert str(path) in lines[0]
    for word in words:
        assert word in lines[0], (word, lines[0])


@pytest.mark.parametrize("compiled", ["yes", "no"])
@pytest.mark.parametrize("case", sorted(CASES))
def test_bad_data_inputs_and_h_are_refused_in_one_line_on_both_paths(case, compiled, tmp_path):
    text, words = CASES[case]
    path = tmp_path / f"{case}.py"
    path.write_text(text)
    _assert_one_line(_verify(path, tmp_path / "out", compiled), path, words)


def test_an_h_nan_at_the_truths_states_is_refused_in_one_line_naming_h(tmp_path):
    """sqrt(x - 100) at states near 0 (the numpy path: a kernel of this model would compile for a minute;
    the compiled path's refusal of a truth's h that is not finite is held by the h_infinite case)."""
    path = tmp_path / "nan_h.py"
    path.write_text(_NAN_H)
    _assert_one_line(_verify(path, tmp_path / "out", "no"), path, ("the truth's h is not finite", "200 of 200"))
