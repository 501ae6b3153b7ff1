"""The simulator's floor for pick's landings (``scenarios.landing_floor``): an open finger that comes down onto a cube
slowly stays under the contact-force limit, and one that comes down at the approach's speed does not, whatever the
layers above do, within a few ticks of the touch. The whole stack runs in the loop (MuJoCo, the QP, the guards)."""

from __future__ import annotations

import pytest

from scenarios.landing_floor import SPIKE_WINDOW_S, land, main
from scenarios.world.tasks.pick import LANDING_SPEED_M_S


def test_a_slow_landing_stays_under_the_limit_and_a_fast_one_goes_over_it_within_the_spike_window():
    slow, fast = land(0.1), land(0.3)
    assert slow.landing_speed_m_s == pytest.approx(0.1, abs=0.01)  # the hand came down at the commanded speed
    assert 1.0 < slow.spike_n < slow.limit_n and slow.ticks_over_limit == 0, slow
    assert fast.landing_speed_m_s > 0.22, fast  # past the fastest landing under the limit (0.18 m/s)
    assert fast.spike_n > 1.5 * fast.limit_n and fast.spike_after_ms <= 1000.0 * SPIKE_WINDOW_S, fast
    assert fast.ticks_over_limit > 0 and fast.peak_n == pytest.approx(fast.spike_n), fast  # the landing is the peak


def test_picks_stack_lands_a_fast_blind_descent_at_its_landing_speed_under_the_limit():
    """The same 0.3 m/s descent with pick's stack as it runs: the descent governor passes the band at the landing
    speed (``StackConfig.landing_speed_m_s``), and the landing stays under the limit."""
    governed = land(0.3, landing_speed=True)
    assert governed.landing_speed_m_s < LANDING_SPEED_M_S + 0.03, governed
    assert governed.spike_n < governed.limit_n and governed.ticks_over_limit == 0, governed


def test_a_landing_speed_out_of_range_is_one_line_naming_the_switch(capsys):
    with pytest.raises(SystemExit):
        main(["--speeds", "2"])
    err = capsys.readouterr().err.strip().splitlines()[-1]
    assert "--speeds" in err and "2" in err
