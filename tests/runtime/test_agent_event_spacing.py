"""A limiter acting on every setpoint (50 Hz on PX4) is logged on a log scale, not each time."""

from app.runtime.agent import _log_spaced


def test_repeating_link_events_are_logged_on_a_log_scale() -> None:
    logged = [n for n in range(1, 20_001) if _log_spaced(n)]
    assert logged == [1, 2, 5, 10, 20, 50, 100, 200, 500, 1000, 2000, 5000, 10_000, 20_000]
    assert not _log_spaced(0)
