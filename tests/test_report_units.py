"""The report's force figures from a trace, without running a cell."""

from __future__ import annotations

import numpy as np

from controller.control.force import NormalForceRegulator
from controller.params import ForceParams
from launch.report_maths import cap_watch_force

CAP_N = ForceParams().cap_n
FILTER_S = ForceParams().filter_s


def _ticks(n: int, t0: float = 0.0) -> np.ndarray:
    return t0 + 1e-3 * np.arange(n)


def test_a_single_tick_spike_of_the_measured_wrench_is_not_time_above_the_cap():
    force = np.full(200, 10.0)
    force[100] = 42.0  # a 1 ms brake transient as a CI run measured it (the true contact force was 27.8 N)
    seen = cap_watch_force(_ticks(200), force, FILTER_S)
    assert force.max() > CAP_N and seen.max() < CAP_N


def test_a_sustained_overload_is_above_the_cap_within_a_few_ticks_and_stays_there():
    force = np.full(300, 10.0)
    force[100:] = 60.0
    above = np.flatnonzero(cap_watch_force(_ticks(300), force, FILTER_S) > CAP_N)
    assert 100 < above[0] <= 110 and np.all(np.diff(above) == 1) and above[-1] == 299


def test_it_is_the_controllers_own_cap_watch_tick_by_tick():
    rng = np.random.default_rng(3)
    t = np.cumsum(rng.uniform(0.5e-3, 3e-3, 500))
    force = rng.uniform(0.0, 55.0, 500)
    watch = NormalForceRegulator(0.3, 8.0, 8.0, CAP_N, FILTER_S)
    expected = [watch.measure(f, dt) for f, dt in zip(force, np.diff(t, prepend=t[0]))]
    np.testing.assert_allclose(cap_watch_force(t, force, FILTER_S), expected, rtol=1e-12, atol=1e-12)


def test_a_restarted_controller_starts_its_filter_again():
    t = np.concatenate([_ticks(50, 10.0), _ticks(50, 0.0)])  # the new controller's robot clock starts over
    force = np.concatenate([np.full(50, 39.0), np.full(50, 5.0)])
    seen = cap_watch_force(t, force, FILTER_S)
    assert seen[49] > 38.0 and seen[50] == 0.0 and abs(seen[-1] - 5.0) < 0.01


def test_a_junction_with_a_held_tick_is_not_the_skills_step():
    """The trace's accelerations are executed (x scale^2): a tick the robot held (its scale a dip, the arm's
    progress) on a junction steps the acceleration by itself; the junction is left out, an ordinary one is not."""
    from controller.core import PHASE_CODES
    from interfaces.messages import Phase
    from launch.report_maths import junction_steps

    n, j = 100, 50
    col = {"phase": 0, "ref_ax": 1, "ref_ay": 2, "speed_scale": 3}
    tr = np.zeros((n, 4))
    tr[:, 0] = np.where(np.arange(n) < j, PHASE_CODES[Phase.WIPE], PHASE_CODES[Phase.TRANSITION])
    tr[:, 1] = 3.0 + 0.01 * np.arange(n)  # a smooth acceleration through the junction: 0.01 m/s^2 a tick
    tr[:, 3] = 1.0
    assert junction_steps(tr, col)[1] < 1.5
    held = tr.copy()
    held[j, 3] = 0.94
    held[j, 1] *= 0.94 ** 2  # the held tick's executed acceleration
    assert junction_steps(held, col) == (0.0, 0.0)
    stepped = tr.copy()
    stepped[j:, 1] += 0.3  # the skill's own step at the junction, scale untouched
    assert junction_steps(stepped, col)[1] > 10.0


def test_reports_draw_plots_unless_the_environment_says_0_and_another_value_is_named(monkeypatch):
    import pytest

    from launch.report_options import PLOTS_ENV, plots_from_env

    for value, want in (("", True), ("1", True), ("0", False), ("false", False), ("yes", True)):
        monkeypatch.setenv(PLOTS_ENV, value)
        assert plots_from_env() is want
    monkeypatch.delenv(PLOTS_ENV)
    assert plots_from_env() is True
    monkeypatch.setenv(PLOTS_ENV, "sometimes")
    with pytest.raises(ValueError, match="LAMPS_REPORT_PLOTS must be 0 or 1, got 'sometimes'"):
        plots_from_env()
