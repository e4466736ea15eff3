"""The .tlog writer and the per-vehicle recorder: raw packets, wall-clock stamps, as pymavlink
(and so MAVProxy and QGroundControl) read them back."""

import struct

import pytest
from pymavlink import mavutil
from pymavlink.dialects.v20 import common as mavlink

from app.adapters.tlog import TlogRecorder, TlogWriter


def packed(msg: mavlink.MAVLink_message, system_id: int, component_id: int = 1) -> bytes:
    return bytes(msg.pack(mavlink.MAVLink(None, srcSystem=system_id, srcComponent=component_id)))


def attitude(roll_rad: float, t_ms: int) -> mavlink.MAVLink_message:
    return mavlink.MAVLink_attitude_message(t_ms, roll_rad, 0.0, 1.0, 0.0, 0.0, 0.1)


def read_all(path) -> list[tuple[float, mavlink.MAVLink_message]]:
    reader = mavutil.mavlink_connection(str(path))
    out = []
    while (msg := reader.recv_match()) is not None:
        out.append((msg._timestamp, msg))
    return out


def test_tlog_holds_the_packets_as_sent_with_their_receive_time(tmp_path):
    path = tmp_path / "vehicle-2.tlog"
    packets = [packed(attitude(0.3, 100 * i), 2) for i in range(5)]
    with TlogWriter(path) as log:
        for i, packet in enumerate(packets):
            log.write(1_700_000_000.0 + 0.25 * i, packet)
        assert log.records == 5
    raw = path.read_bytes()
    # record = 8-byte big-endian microseconds + the packet, byte for byte
    assert raw[:8] == struct.pack(">Q", 1_700_000_000_000_000)
    assert raw[8 : 8 + len(packets[0])] == packets[0]
    back = read_all(path)
    assert [m.get_type() for _, m in back] == ["ATTITUDE"] * 5
    assert back[-1][1].roll == pytest.approx(0.3)
    assert [t for t, _ in back] == pytest.approx([1_700_000_000.0 + 0.25 * i for i in range(5)])


def test_tlog_stamps_never_go_back_when_the_wall_clock_does(tmp_path):
    path = tmp_path / "x.tlog"
    with TlogWriter(path) as log:
        log.write(1_700_000_010.0, packed(attitude(0.1, 0), 1))
        log.write(1_700_000_005.0, packed(attitude(0.1, 100), 1))  # clock stepped back
    stamps = [t for t, _ in read_all(path)]
    assert stamps == [pytest.approx(1_700_000_010.0)] * 2


def test_tlog_refuses_writes_outside_its_context_and_bad_stamps(tmp_path):
    log = TlogWriter(tmp_path / "x.tlog")
    with pytest.raises(RuntimeError, match="outside"):
        log.write(0.0, b"")
    with log, pytest.raises(ValueError, match="finite"):
        log.write(float("nan"), b"")


def test_recorder_keeps_one_log_per_vehicle_and_ignores_other_systems(tmp_path):
    with TlogRecorder.for_vehicles(tmp_path, [1, 2]) as rec:
        rec.write(1, 1_700_000_000.0, packed(attitude(0.1, 0), 1))
        rec.write(2, 1_700_000_000.0, packed(attitude(0.2, 0), 2))
        rec.write(2, 1_700_000_000.1, packed(attitude(0.2, 100), 2, 100))
        rec.write(7, 1_700_000_000.0, packed(attitude(0.7, 0), 7))
        assert (rec.records(1), rec.records(2), rec.records(7)) == (1, 2, 0)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["vehicle-1.tlog", "vehicle-2.tlog"]
    two = read_all(tmp_path / "vehicle-2.tlog")
    assert [m.get_srcComponent() for _, m in two] == [1, 100]


def test_recorder_that_cannot_write_logs_an_error_and_goes_on(tmp_path, caplog):
    blocker = tmp_path / "not-a-folder"
    blocker.write_text("x", encoding="utf-8")
    rec = TlogRecorder({1: blocker / "vehicle-1.tlog", 2: tmp_path / "vehicle-2.tlog"})
    with rec:
        rec.write(1, 1_700_000_000.0, packed(attitude(0.1, 0), 1))  # ignored: no log
        rec.write(2, 1_700_000_000.0, packed(attitude(0.2, 0), 2))
    assert "vehicle 1: flight log" in caplog.text
    assert len(read_all(tmp_path / "vehicle-2.tlog")) == 1
