"""The closed loop's trajectory is the recorded one (``trajectory.py`` says when it was).

The fixtures (``fixtures/trajectory_<mode>.npz``, written by ``trajectory.py``) hold every
message of a 12-s run in each mode with a mode switch half way. The run now must give the
same messages: the same strokes at the same times, the same plans, the same body states,
to within floating-point noise (rtol 1e-9). Any change to when a stroke ends or what a
sensor reports would move the trajectory by far more than that.
"""

import numpy as np
import pytest

from backend.loop.trajectory import FIXTURES, SCENARIOS, run


@pytest.mark.parametrize("mode", list(SCENARIOS))
def test_the_trajectory_is_the_recorded_one(mode):
    old = np.load(FIXTURES / f"trajectory_{mode}.npz")
    new = run(mode)
    assert sorted(new) == sorted(old.files)
    for key in old.files:
        a, b = old[key], new[key]
        assert a.shape == b.shape, f"{key}: {b.shape} messages, recorded {a.shape}"
        np.testing.assert_allclose(b, a, rtol=1e-9, atol=1e-12, equal_nan=True, err_msg=key)
    # the run did what the scenario is for: strokes in both modes, plans made
    assert old["counters"][0] > 10
    assert old["fin.0.strouhal"].shape[0] > 5
