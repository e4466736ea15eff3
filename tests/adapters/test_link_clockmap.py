"""The vehicle link's boot-clock map: boot clocks seconds apart, jitter, reboots, jumps."""

import random

import pytest

from app.adapters.vehicle.mavsdk.clockmap import BootClockMap


def feed(
    clock: BootClockMap, boot0_s: float, host0_s: float, n: int, rng: random.Random
) -> list[float]:
    """``n`` frames at 10 Hz with 1-40 ms of transport delay; their mission times."""
    out = []
    for k in range(n):
        boot = boot0_s + 0.1 * k
        host = host0_s + 0.1 * k + rng.uniform(0.001, 0.040)
        t, _ = clock.update(boot, host)
        out.append(t)
    return out


def test_boot_clocks_seconds_or_minutes_apart_map_to_one_mission_time() -> None:
    rng = random.Random(3)
    # the same instants (host 5.0 + 0.1 k) seen by vehicles booted 2.1 s, 4.4 s and 180 s before
    maps = [BootClockMap() for _ in range(3)]
    times = [
        feed(m, boot0, 5.0, 200, rng) for m, boot0 in zip(maps, (7.1, 9.4, 185.0), strict=True)
    ]
    for k in range(20, 200):
        instants = [times[v][k] for v in range(3)]
        assert max(instants) - min(instants) < 0.04
        assert abs(instants[0] - (5.0 + 0.1 * k)) < 0.04  # and that time is the host's


def test_a_slow_frame_does_not_move_the_offset() -> None:
    clock = BootClockMap()
    for k in range(50):
        clock.update(10.0 + 0.1 * k, 1.0 + 0.1 * k + 0.002)
    offset = clock.offset_s
    assert offset is not None
    assert offset == pytest.approx(-9.0 + 0.002)
    t, rebase = clock.update(15.0, 6.0 + 1.5)  # a frame that waited 1.5 s in a busy host
    assert rebase is None
    assert clock.offset_s == offset
    assert t == pytest.approx(15.0 + offset)


def test_a_reboot_rebases_and_mission_time_goes_on() -> None:
    clock = BootClockMap(jump_s=5.0)
    for k in range(100):
        last_t, _ = clock.update(300.0 + 0.1 * k, 20.0 + 0.1 * k + 0.003)
    # rebooted: 8 s later on the host, its clock starts again at 0.5 s
    t, rebase = clock.update(0.5, 20.0 + 9.9 + 8.0 + 0.003)
    assert rebase is not None
    assert rebase.reason == "reboot"
    assert rebase.previous_boot_s == pytest.approx(309.9)
    assert t == pytest.approx(37.903)
    assert t > last_t
    t2, rebase2 = clock.update(0.6, 38.0 + 0.004)
    assert rebase2 is None
    assert t2 == pytest.approx(38.003)
    assert clock.rebases == 1


def test_a_boot_clock_leaping_ahead_rebases() -> None:
    clock = BootClockMap(jump_s=5.0)
    for k in range(20):
        clock.update(50.0 + 0.1 * k, 0.1 * k)
    t, rebase = clock.update(100.0, 2.0)  # 48 s of boot time in 0.1 s of host time
    assert rebase is not None
    assert rebase.reason == "jump"
    assert t == pytest.approx(2.0)


def test_a_late_or_repeated_frame_is_not_a_sample() -> None:
    clock = BootClockMap()
    clock.update(10.0, 1.0)
    clock.update(10.1, 1.1)
    t, rebase = clock.update(10.05, 0.9)  # older than the last, and would lower the offset
    assert rebase is None
    assert t == pytest.approx(10.05 - 9.0)
    assert clock.offset_s == pytest.approx(-9.0)


def test_a_boot_clock_running_slow_is_followed_once_the_window_slid_past() -> None:
    clock = BootClockMap(window_s=2.0)
    for k in range(30):  # boot clock at 0.9x the host's: the least offset grows
        clock.update(0.09 * k, 0.1 * k)
    t, _ = clock.update(0.09 * 30, 3.0)
    assert t == pytest.approx(3.0, abs=0.25)


@pytest.mark.parametrize("bad", [float("nan"), float("inf")])
def test_non_finite_times_are_refused(bad: float) -> None:
    with pytest.raises(ValueError, match="finite"):
        BootClockMap().update(bad, 1.0)
    with pytest.raises(ValueError, match="window_s"):
        BootClockMap(window_s=bad)
