"""Geodesy about the simulator's origin: pymap3d round trips, and the anchored fast path
agrees with pymap3d to a millimetre."""

import numpy as np
import pytest

from sitl.geodesy import AnchoredGeodesy, Geodesy

ORIGIN = Geodesy(47.397742, 8.545594, 488.0)


def test_round_trip_and_the_origin():
    assert ORIGIN.to_geodetic(0.0, 0.0, 0.0) == pytest.approx((47.397742, 8.545594, 488.0))
    lat, lon, alt = ORIGIN.to_geodetic(1500.0, -2500.0, 100.0)
    assert ORIGIN.to_local(lat, lon, alt) == pytest.approx((1500.0, -2500.0, 100.0), abs=1e-6)
    assert lat < 47.397742  # south
    assert lon > 8.545594  # east


def test_anchored_conversion_matches_pymap3d_within_a_millimetre():
    rng = np.random.default_rng(0)
    anchored = AnchoredGeodesy(ORIGIN, slot_count=4)
    slots = np.arange(4)
    points = np.column_stack([rng.uniform(-5000, 5000, (4, 2)), np.full(4, 120.0)])
    worst_m = 0.0
    for step in range(600):
        points[:, :2] += rng.normal(0.0, 4.0, (4, 2))  # wandering, re-anchoring every ~100 m
        lla = anchored.to_geodetic(slots, points)
        if step % 20 == 0:
            for k in range(4):
                back = np.array(ORIGIN.to_local(*lla[k]))
                worst_m = max(worst_m, float(np.max(np.abs(back - points[k]))))
    assert worst_m < 1e-3
