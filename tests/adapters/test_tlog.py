import math

import pytest
from pymavlink import mavutil

from app.adapters.tlog import TlogSample, TlogWriter


def test_tlog_replays_in_pymavlink(tmp_path):
    path = tmp_path / "vehicle-1.tlog"
    with TlogWriter(path, system_id=2, epoch_s=1_700_000_000.0) as log:
        for i in range(20):
            t = 0.1 * i
            log.write(
                TlogSample(
                    t_s=t,
                    lat_deg=47.397742 + 1e-5 * i,
                    lon_deg=8.545594,
                    alt_m=488.0 + 100.0,
                    relative_alt_m=100.0,
                    v_north_m_s=14.0,
                    v_east_m_s=0.0,
                    course_rad=math.radians(350.0),
                    speed_m_s=14.0,
                    roll_rad=0.2,
                )
            )
        log.write(TlogSample(math.nan, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0))
        assert log.records == 80
    reader = mavutil.mavlink_connection(str(path))
    positions = []
    kinds = set()
    while (msg := reader.recv_match()) is not None:
        kinds.add(msg.get_type())
        assert msg.get_srcSystem() == 2
        if msg.get_type() == "GLOBAL_POSITION_INT":
            positions.append(msg)
    assert kinds == {"HEARTBEAT", "GLOBAL_POSITION_INT", "ATTITUDE", "VFR_HUD"}
    assert len(positions) == 20
    assert positions[-1].lat == round((47.397742 + 19e-5) * 1e7)
    assert positions[-1].hdg == 35000
    assert positions[-1].time_boot_ms == 1900
    assert reader.timestamp == pytest.approx(1_700_000_001.9)


def test_tlog_refuses_writes_outside_its_context(tmp_path):
    log = TlogWriter(tmp_path / "x.tlog", system_id=1, epoch_s=0.0)
    with pytest.raises(RuntimeError, match="outside"):
        log.write(TlogSample(0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0))
