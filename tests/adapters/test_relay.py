"""The MAVLink relay between a vehicle, the app and a ground station, on real loopback UDP with
pymavlink peers: bytes passed on unchanged, addressed packets routed to the side that has the
system, both directions recorded in the vehicle's .tlog, and its own faults kept out of the way."""

import asyncio
import json
import os
import signal
import socket
import subprocess
import sys
import time

import pytest
from pymavlink import mavutil
from pymavlink.dialects.v20 import common as mavlink

from app.adapters.tlog import TlogRecorder
from app.adapters.vehicle.mavsdk.packets import (
    TARGET_OFFSETS,
    broadcast_timesync_answers,
    split_packets,
    split_stream,
)
from app.adapters.vehicle.mavsdk.relay import MavlinkRelay
from app.adapters.vehicle.mavsdk.relay_process import RelayProcess, RelaySpec
from app.adapters.vehicle.mavsdk.urls import (
    UdpEndpoint,
    parse_gcs_endpoint,
    udp_endpoint_of_url,
)
from app.compose.parts import relay_specs
from app.errors import ConfigError, LinkError
from sitl.px4 import Px4TimesyncAnswer
from tests.support.mosquitto import refused_port

APP_ID, GCS_ID, VEHICLE_ID = 245, 255, 3


def pack(msg: mavlink.MAVLink_message, system_id: int, component_id: int = 1, v1: bool = False):
    mav = mavlink.MAVLink(None, srcSystem=system_id, srcComponent=component_id)
    if v1:
        mav.WIRE_PROTOCOL_VERSION = "1.0"
        mav.protocol_marker = 0xFE
        mav.mavlink20 = lambda: False
    return bytes(msg.pack(mav))


def heartbeat(kind: int = mavlink.MAV_TYPE_GCS) -> mavlink.MAVLink_message:
    return mavlink.MAVLink_heartbeat_message(kind, mavlink.MAV_AUTOPILOT_INVALID, 0, 0, 0, 3)


def command_long(target: int) -> mavlink.MAVLink_message:
    return mavlink.MAVLink_command_long_message(
        target, 1, mavlink.MAV_CMD_COMPONENT_ARM_DISARM, 0, 1, 0, 0, 0, 0, 0, 0
    )


def ack(target: int) -> mavlink.MAVLink_message:
    return mavlink.MAVLink_command_ack_message(
        mavlink.MAV_CMD_COMPONENT_ARM_DISARM, 0, 0, 0, target, 190
    )


def decode(data: bytes) -> list[mavlink.MAVLink_message]:
    parser = mavlink.MAVLink(None)
    return list(parser.parse_buffer(data) or [])


class Peer(asyncio.DatagramProtocol):
    """A UDP socket on loopback that keeps what it receives."""

    def __init__(self) -> None:
        self.received: asyncio.Queue[tuple[bytes, tuple[str, int]]] = asyncio.Queue()
        self.transport: asyncio.DatagramTransport | None = None

    def datagram_received(self, data: bytes, addr: tuple[str, int]) -> None:
        self.received.put_nowait((data, addr))

    @classmethod
    async def open(cls, port: int = 0) -> "Peer":
        loop = asyncio.get_running_loop()
        transport, peer = await loop.create_datagram_endpoint(cls, local_addr=("127.0.0.1", port))
        peer.transport = transport
        return peer

    @property
    def port(self) -> int:
        assert self.transport is not None
        return int(self.transport.get_extra_info("sockname")[1])

    def send(self, data: bytes, port: int) -> None:
        assert self.transport is not None
        self.transport.sendto(data, ("127.0.0.1", port))

    async def next(self, timeout_s: float = 2.0) -> bytes:
        async with asyncio.timeout(timeout_s):
            return (await self.received.get())[0]

    async def nothing(self, wait_s: float = 0.2) -> bool:
        await asyncio.sleep(wait_s)
        return self.received.empty()

    def close(self) -> None:
        if self.transport is not None:
            self.transport.close()


def free_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def app_port(relay: MavlinkRelay) -> int:
    return int(relay.app_url.rsplit(":", 1)[1])


# --- framing --------------------------------------------------------------------------------


def test_split_finds_v1_and_v2_packets_their_sender_and_target_and_skips_garbage():
    v2 = pack(command_long(7), APP_ID, 190)
    v1 = pack(heartbeat(), 9, 1, v1=True)
    cam = pack(mavlink.MAVLink_attitude_message(1, 0.2, 0, 0, 0, 0, 0), 3, 100)
    data = b"\x00\x01junk" + v2 + v1 + cam + v2[:7]  # a packet cut short at the end
    packets, skipped = split_packets(data)
    assert [(p.system_id, p.component_id, p.msg_id) for p in packets] == [
        (APP_ID, 190, mavlink.MAVLINK_MSG_ID_COMMAND_LONG),
        (9, 1, mavlink.MAVLINK_MSG_ID_HEARTBEAT),
        (3, 100, mavlink.MAVLINK_MSG_ID_ATTITUDE),
    ]
    assert [p.target_system for p in packets] == [7, 0, 0]
    assert data[packets[0].start : packets[0].end] == v2
    assert data[packets[1].start : packets[1].end] == v1
    assert skipped == 6 + 7


def test_target_offsets_match_the_dialect_for_setpoints_and_commands():
    # the relay routes by these: SET_POSITION_TARGET_LOCAL_NED's target_system follows 13 fields
    assert TARGET_OFFSETS[mavlink.MAVLINK_MSG_ID_SET_POSITION_TARGET_LOCAL_NED] == 4 + 11 * 4 + 2
    assert TARGET_OFFSETS[mavlink.MAVLINK_MSG_ID_COMMAND_LONG] == 30
    assert mavlink.MAVLINK_MSG_ID_HEARTBEAT not in TARGET_OFFSETS
    setpoint = mavlink.MAVLink_set_position_target_local_ned_message(
        0, 2, 1, 1, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0
    )
    packets, _ = split_packets(pack(setpoint, APP_ID))
    assert packets[0].target_system == 2


# --- endpoints ------------------------------------------------------------------------------


def test_gcs_endpoints_parse_as_px4_sitl_and_mavproxy_write_them():
    assert parse_gcs_endpoint("127.0.0.1:14550") == UdpEndpoint("udpout", "127.0.0.1", 14550)
    assert parse_gcs_endpoint("udpin:0.0.0.0:14560").mode == "udpin"
    assert parse_gcs_endpoint("udpout://10.0.0.2:14550").spec == "udpout:10.0.0.2:14550"
    for bad in ("14550", "udpout:host:", "host:99999", "udpin::14550"):
        with pytest.raises(ConfigError, match="ground station endpoint"):
            parse_gcs_endpoint(bad)
    assert udp_endpoint_of_url("udpin://0.0.0.0:14540") == UdpEndpoint("udpin", "0.0.0.0", 14540)
    assert udp_endpoint_of_url("serial:///dev/ttyUSB0:57600") is None
    assert udp_endpoint_of_url("tcpin://0.0.0.0:5760") is None
    assert udp_endpoint_of_url("tcp://127.0.0.1:5760") == UdpEndpoint("tcpout", "127.0.0.1", 5760)
    assert udp_endpoint_of_url("tcpout://127.0.0.1:5770") == UdpEndpoint(
        "tcpout", "127.0.0.1", 5770
    )


# --- the relay ------------------------------------------------------------------------------


async def test_relay_passes_traffic_both_ways_and_records_it_in_the_vehicles_tlog(tmp_path):
    """The vehicle sends to the relay's udpin port (as the simulator and PX4 SITL send to
    14540+i); the app talks udpout to the relay; the tlog holds both directions, camera
    included, stamped with the wall clock."""
    port = free_port()
    vehicle, app = await Peer.open(), await Peer.open()
    before = time.time()
    with TlogRecorder.for_vehicles(tmp_path, [VEHICLE_ID]) as rec:
        async with MavlinkRelay(UdpEndpoint("udpin", "127.0.0.1", port), recorder=rec) as relay:
            assert relay.app_url.startswith("udpout://127.0.0.1:")
            vehicle.send(pack(heartbeat(mavlink.MAV_TYPE_FIXED_WING), VEHICLE_ID), port)
            app_hb = pack(heartbeat(), APP_ID, 190)
            app.send(app_hb, app_port(relay))  # the app is learned from its first datagram
            assert await vehicle.next() == app_hb
            attitude = pack(mavlink.MAVLink_attitude_message(5, 0.3, 0, 0, 0, 0, 0), VEHICLE_ID)
            camera = pack(
                mavlink.MAVLink_camera_tracking_geo_status_message(
                    1, 473977420, 85455940, 0, 3, 0, 0, 0, 0, 0, 100, 0, 0, 0
                ),
                VEHICLE_ID,
                100,
            )
            vehicle.send(attitude, port)
            vehicle.send(camera, port)
            assert await app.next() == attitude  # unchanged, byte for byte
            assert await app.next() == camera
            command = pack(command_long(VEHICLE_ID), APP_ID, 190)
            app.send(command, app_port(relay))
            assert await vehicle.next() == command
            vehicle.send(pack(ack(APP_ID), VEHICLE_ID), port)
            assert decode(await app.next())[0].get_type() == "COMMAND_ACK"
    after = time.time()
    vehicle.close()
    app.close()
    reader = mavutil.mavlink_connection(str(tmp_path / f"vehicle-{VEHICLE_ID}.tlog"))
    seen = []
    while (msg := reader.recv_match()) is not None:
        seen.append((msg.get_srcSystem(), msg.get_srcComponent(), msg.get_type(), msg._timestamp))
    kinds = [(s, c, k) for s, c, k, _ in seen]
    assert kinds == [
        (VEHICLE_ID, 1, "HEARTBEAT"),
        (APP_ID, 190, "HEARTBEAT"),
        (VEHICLE_ID, 1, "ATTITUDE"),
        (VEHICLE_ID, 100, "CAMERA_TRACKING_GEO_STATUS"),
        (APP_ID, 190, "COMMAND_LONG"),
        (VEHICLE_ID, 1, "COMMAND_ACK"),
    ]
    stamps = [t for *_, t in seen]
    assert stamps == sorted(stamps)
    assert before - 0.01 <= stamps[0]
    assert stamps[-1] <= after + 0.01


async def test_relay_serves_a_ground_station_without_crossing_the_apps_traffic(tmp_path):
    """udpout to the ground station (as PX4 SITL sends to 14550): it sees the vehicle's stream;
    what it sends reaches the vehicle; ACKs go back only to whoever asked."""
    vehicle, app, gcs = await Peer.open(), await Peer.open(), await Peer.open()
    port = free_port()
    with TlogRecorder.for_vehicles(tmp_path, [VEHICLE_ID]) as rec:
        async with MavlinkRelay(
            UdpEndpoint("udpin", "127.0.0.1", port),
            recorder=rec,
            gcs=UdpEndpoint("udpout", "127.0.0.1", gcs.port),
            system_ids=frozenset({VEHICLE_ID}),  # its broadcasts are logged before it is heard
        ) as relay:
            app.send(pack(heartbeat(), APP_ID, 190), app_port(relay))
            position = pack(
                mavlink.MAVLink_global_position_int_message(1, 1, 2, 3, 4, 0, 0, 0, 0), VEHICLE_ID
            )
            vehicle.send(position, port)
            assert await app.next() == position
            assert await gcs.next() == position
            # the ground station answers from its port: it commands the vehicle
            gcs_port_of_relay = (await _sender(gcs, vehicle, port, position))[1][1]
            assert await app.next() == position  # the app's copy of it
            mode = pack(command_long(VEHICLE_ID), GCS_ID, 190)
            gcs.send(mode, gcs_port_of_relay)
            assert await vehicle.next() == mode
            # a command for another vehicle (a GCS sends on every link) stays off this one
            gcs.send(pack(command_long(VEHICLE_ID + 1), GCS_ID, 190), gcs_port_of_relay)
            assert await vehicle.nothing()
            assert relay.counters.gcs_refused == 1
            # the vehicle's ACK to the ground station does not reach the app, and back
            vehicle.send(pack(ack(GCS_ID), VEHICLE_ID), port)
            assert decode(await gcs.next())[0].target_system == GCS_ID
            assert await app.nothing()
            vehicle.send(pack(ack(APP_ID), VEHICLE_ID), port)
            assert decode(await app.next())[0].target_system == APP_ID
            assert await gcs.nothing()
            assert app.received.empty()
    for peer in (vehicle, app, gcs):
        peer.close()
    reader = mavutil.mavlink_connection(str(tmp_path / f"vehicle-{VEHICLE_ID}.tlog"))
    senders = set()
    while (msg := reader.recv_match()) is not None:
        senders.add(msg.get_srcSystem())
    assert senders == {VEHICLE_ID, APP_ID, GCS_ID}  # what the ground station sent is there too


async def _sender(
    gcs: Peer, vehicle: Peer, port: int, position: bytes
) -> tuple[bytes, tuple[str, int]]:
    """The relay's ground-station socket address, from one more datagram it passes on."""
    vehicle.send(position, port)
    async with asyncio.timeout(2.0):
        return await gcs.received.get()


async def test_relay_goes_on_when_nobody_listens_on_the_ground_station_port(tmp_path):
    vehicle, app = await Peer.open(), await Peer.open()
    port, nobody = free_port(), free_port()
    async with MavlinkRelay(
        UdpEndpoint("udpin", "127.0.0.1", port), gcs=UdpEndpoint("udpout", "127.0.0.1", nobody)
    ) as relay:
        app.send(pack(heartbeat(), APP_ID, 190), app_port(relay))
        for i in range(20):
            msg = mavlink.MAVLink_attitude_message(i, 0.1, 0, 0, 0, 0, 0)
            vehicle.send(pack(msg, VEHICLE_ID), port)
            assert decode(await app.next())[0].time_boot_ms == i
        assert relay.counters.faults == 0
    vehicle.close()
    app.close()


async def test_a_taken_vehicle_port_is_named_and_a_taken_gcs_port_only_costs_the_gcs(caplog):
    taken = await Peer.open()
    with pytest.raises(LinkError, match=f"UDP 127.0.0.1:{taken.port} .*in use|{taken.port}"):
        async with MavlinkRelay(UdpEndpoint("udpin", "127.0.0.1", taken.port)):
            pass
    async with MavlinkRelay(
        UdpEndpoint("udpin", "127.0.0.1", free_port()),
        gcs=UdpEndpoint("udpin", "127.0.0.1", taken.port),
    ) as relay:
        assert relay.gcs is None
    assert f"cannot open UDP 127.0.0.1:{taken.port}" in caplog.text
    taken.close()


async def test_garbage_from_the_vehicle_is_passed_on_but_not_recorded(tmp_path):
    vehicle, app = await Peer.open(), await Peer.open()
    port = free_port()
    with TlogRecorder.for_vehicles(tmp_path, [VEHICLE_ID]) as rec:
        async with MavlinkRelay(UdpEndpoint("udpin", "127.0.0.1", port), recorder=rec) as relay:
            app.send(pack(heartbeat(), APP_ID, 190), app_port(relay))
            vehicle.send(b"\xfd\x09garbage", port)
            assert await app.next() == b"\xfd\x09garbage"  # the relay is not a filter
            assert relay.counters.bytes_skipped == 9
            assert relay.counters.faults == 0
    vehicle.close()
    app.close()
    # only the app's heartbeat would have been recorded, and no vehicle was heard yet
    assert (tmp_path / f"vehicle-{VEHICLE_ID}.tlog").read_bytes() == b""


# --- a TCP vehicle (ArduPilot SITL's 5760) --------------------------------------------------


def test_px4s_timesync_answers_are_passed_on_as_broadcasts_and_nothing_else_is_touched() -> None:
    """PX4 v1.16 answers TIMESYNC with uninitialised target bytes (88, 28 in a real run), which
    MAVSDK takes for another system's: the relay cuts them, so the answer is a broadcast with
    a good checksum and the same tc1 / ts1; requests, answers without target bytes, signed
    packets and the other packets of the datagram stay byte for byte."""
    answer = pack(Px4TimesyncAnswer(123_000_000, 987_654_321), VEHICLE_ID)
    assert answer[1] == 18  # the payload carries the two target bytes
    beat = pack(heartbeat(mavlink.MAV_TYPE_FIXED_WING), VEHICLE_ID)
    data = beat + answer + beat
    packets, _ = split_packets(data)
    out = broadcast_timesync_answers(data, packets)
    assert out != data
    assert out[: len(beat)] == beat
    assert out[-len(beat) :] == beat
    fixed = out[len(beat) : -len(beat)]
    assert fixed[1] == 16  # no target bytes: a broadcast
    (msg,) = decode(fixed)  # pymavlink checks the CRC
    assert (msg.get_type(), msg.tc1, msg.ts1) == ("TIMESYNC", 123_000_000, 987_654_321)
    assert msg.get_srcSystem() == VEHICLE_ID
    # what MAVSDK decodes with the extension fields: a 16-byte payload reads target 0
    plain = pack(mavlink.MAVLink_timesync_message(5, 6), VEHICLE_ID)  # ArduPlane's answer
    request = pack(Px4TimesyncAnswer(0, 42), VEHICLE_ID)  # tc1 0: a request, even with bytes
    for untouched in (plain, request):
        unchanged, _ = split_packets(untouched)
        assert broadcast_timesync_answers(untouched, unchanged) is untouched
    signed = bytearray(answer)
    signed[2] |= 0x01
    signed_bytes = bytes(signed) + bytes(13)
    packets, _ = split_packets(signed_bytes)
    assert broadcast_timesync_answers(signed_bytes, packets) is signed_bytes


def test_split_stream_keeps_a_packet_cut_short_for_the_next_read():
    one = pack(heartbeat(mavlink.MAV_TYPE_FIXED_WING), VEHICLE_ID)
    two = pack(mavlink.MAVLink_attitude_message(5, 0.3, 0, 0, 0, 0, 0), VEHICLE_ID)
    data = one + two[:9]
    packets, skipped, end = split_stream(data)
    assert [p.msg_id for p in packets] == [mavlink.MAVLINK_MSG_ID_HEARTBEAT]
    assert (skipped, end) == (0, len(one))
    packets, _, end = split_stream(data[end:] + two[9:])
    assert [p.msg_id for p in packets] == [mavlink.MAVLINK_MSG_ID_ATTITUDE]
    assert end == len(two)


async def test_a_tcp_vehicle_is_relayed_packet_by_packet_and_reconnected(tmp_path):
    """The vehicle is a TCP server (ArduPilot SITL): its byte stream, cut anywhere, reaches the
    app as whole packets; the app's packets reach it; a dropped connection is made again."""
    connections: asyncio.Queue[tuple[asyncio.StreamReader, asyncio.StreamWriter]]
    connections = asyncio.Queue()

    async def accept(reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        await connections.put((reader, writer))

    server = await asyncio.start_server(accept, "127.0.0.1", 0)
    port = server.sockets[0].getsockname()[1]
    app = await Peer.open()
    with TlogRecorder.for_vehicles(tmp_path, [VEHICLE_ID]) as rec:
        async with (
            server,
            MavlinkRelay(
                UdpEndpoint("tcpout", "127.0.0.1", port),
                recorder=rec,
                system_ids=frozenset({VEHICLE_ID}),
            ) as relay,
        ):
            reader, writer = await asyncio.wait_for(connections.get(), 2.0)
            app_hb = pack(heartbeat(), APP_ID, 190)
            app.send(app_hb, app_port(relay))
            assert await asyncio.wait_for(reader.readexactly(len(app_hb)), 2.0) == app_hb
            one = pack(heartbeat(mavlink.MAV_TYPE_FIXED_WING), VEHICLE_ID)
            two = pack(mavlink.MAVLink_attitude_message(5, 0.3, 0, 0, 0, 0, 0), VEHICLE_ID)
            writer.write(one + two[:7])  # the second packet cut in two
            await writer.drain()
            assert await app.next() == one
            writer.write(two[7:])
            await writer.drain()
            assert await app.next() == two
            writer.close()  # the vehicle drops the connection: the relay makes it again
            reader, writer = await asyncio.wait_for(connections.get(), 5.0)
            writer.write(two)
            await writer.drain()
            assert await app.next() == two
            writer.close()
    app.close()
    kinds = [m.get_type() for m in read_messages(tmp_path / f"vehicle-{VEHICLE_ID}.tlog")]
    assert kinds == ["HEARTBEAT", "HEARTBEAT", "ATTITUDE", "ATTITUDE"]


async def test_a_tcp_vehicle_that_is_not_there_is_named():
    with refused_port() as port, pytest.raises(LinkError, match=f"TCP 127.0.0.1:{port}"):
        async with MavlinkRelay(UdpEndpoint("tcpout", "127.0.0.1", port)):
            pass


def read_messages(path) -> list[mavlink.MAVLink_message]:
    reader = mavutil.mavlink_connection(str(path))
    out = []
    while (msg := reader.recv_match()) is not None:
        out.append(msg)
    return out


async def test_relays_in_a_process_of_their_own_forward_while_the_mission_loop_is_busy(
    tmp_path, caplog
) -> None:
    """The mission runs its relays in a RelayProcess: a datagram from the vehicle reaches the
    app while the mission's own loop is blocked in a long tick, both directions go into the
    vehicle's .tlog, the counters come back, and the relay is gone with the block."""
    vehicle = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    app = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    try:
        vehicle.bind(("127.0.0.1", 0))
        app.bind(("127.0.0.1", 0))
        app.settimeout(2.0)
        endpoint = udp_endpoint_of_url(f"udpout://127.0.0.1:{vehicle.getsockname()[1]}")
        assert endpoint is not None
        tlog = tmp_path / f"vehicle-{VEHICLE_ID}.tlog"
        spec = RelaySpec(endpoint, system_ids=frozenset({VEHICLE_ID}), name="apart")
        async with RelayProcess([spec], {VEHICLE_ID: tlog}) as relays:
            (link,) = relays.links
            assert link.description == f"vehicle link {endpoint.url}, ground station not served"
            port = int(link.app_url.rsplit(":", 1)[1])
            app.sendto(pack(heartbeat(), APP_ID), ("127.0.0.1", port))
            _, relay_addr = await asyncio.to_thread(vehicle.recvfrom, 4096)
            beat = pack(heartbeat(mavlink.MAV_TYPE_FIXED_WING), VEHICLE_ID)
            sent = time.monotonic()
            vehicle.sendto(beat, relay_addr)
            # this loop blocked (as in a long tick) while the app waits for the datagram
            data, _ = app.recvfrom(4096)
            waited_s = time.monotonic() - sent
        assert data == beat
        assert waited_s < 0.2
        assert "ended on its own" not in caplog.text  # let go, not lost
        assert relays.counters == [
            {**relays.counters[0], "from_vehicle": 1, "from_app": 1, "faults": 0}
        ]
        seen = [m.get_srcSystem() for m in read_messages(tlog)]
        assert seen == [APP_ID, VEHICLE_ID]
        # closed: its sockets are gone
        app.sendto(pack(heartbeat(), APP_ID), ("127.0.0.1", port))
        vehicle.settimeout(0.3)
        with pytest.raises(TimeoutError):
            vehicle.recvfrom(4096)
    finally:
        vehicle.close()
        app.close()


async def test_a_relay_process_that_cannot_open_a_vehicle_port_names_it() -> None:
    taken = await Peer.open()
    try:
        spec = RelaySpec(UdpEndpoint("udpin", "127.0.0.1", taken.port))
        with pytest.raises(LinkError, match=f"127.0.0.1:{taken.port}"):
            async with RelayProcess([spec]):
                pass
    finally:
        taken.close()


async def test_a_relay_process_that_ends_on_its_own_is_reported(caplog) -> None:
    """Killed in flight (out of memory, a crash): an error says the vehicles behind it are
    silent from now on; leaving the block afterwards raises nothing."""
    spec = RelaySpec(UdpEndpoint("udpin", "127.0.0.1", free_port()))
    async with RelayProcess([spec]) as relays:
        os.kill(relays.pid, signal.SIGKILL)
        async with asyncio.timeout(5.0):
            assert await relays.wait() == -signal.SIGKILL
        assert "ended on its own (exit code -9)" in caplog.text
        assert "silent from now on" in caplog.text
    assert relays.counters == []


def test_a_relay_process_whose_mission_is_gone_ends_quietly() -> None:
    """The mission killed outright: the relay process sees its input end, cannot send its
    counters to anyone, and ends with exit code 0 and no traceback."""
    spec = RelaySpec(UdpEndpoint("udpin", "127.0.0.1", free_port()))
    child = subprocess.Popen(
        [sys.executable, "-m", "app.adapters.vehicle.mavsdk.relay_process"],
        stdin=subprocess.PIPE,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
    )
    assert child.stdin is not None
    assert child.stdout is not None
    assert child.stderr is not None
    try:
        child.stdin.write((json.dumps({"relays": [spec.to_json()]}) + "\n").encode())
        child.stdin.flush()
        assert "link" in json.loads(child.stdout.readline())
        assert json.loads(child.stdout.readline()) == {"ready": True}
        child.stdout.close()  # as a killed mission's end of the pipe
        child.stdin.close()
        assert child.wait(timeout=10.0) == 0
        errors = child.stderr.read().decode()
        assert "Traceback" not in errors
        assert "BrokenPipeError" not in errors
    finally:
        child.kill()
        child.wait()
        child.stderr.close()


def test_a_relay_spec_goes_through_json_unchanged() -> None:
    spec = RelaySpec(
        UdpEndpoint("tcpout", "10.0.0.2", 5760),
        gcs=UdpEndpoint("udpin", "0.0.0.0", 14550),
        gcs_index=3,
        system_ids=frozenset({4, 7}),
        name="relay tcpout://10.0.0.2:5760",
    )
    assert RelaySpec.from_json(json.loads(json.dumps(spec.to_json()))) == spec


def test_every_connection_the_relay_can_open_gets_one_and_the_others_are_flown_directly(caplog):
    gcs = UdpEndpoint("udpin", "0.0.0.0", 14550)
    urls = ["udpin://0.0.0.0:14540", "serial:///dev/ttyUSB0:57600", "tcpout://127.0.0.1:5760"]
    specs = relay_specs(urls, [0, 1, 2], gcs)
    assert sorted(specs) == [0, 2]
    assert specs[0] == RelaySpec(
        UdpEndpoint("udpin", "0.0.0.0", 14540),
        gcs=gcs,
        gcs_index=0,
        system_ids=frozenset({1}),
        name="relay udpin://0.0.0.0:14540",
    )
    assert (specs[2].gcs_index, specs[2].system_ids) == (2, frozenset({3}))
    assert "serial:///dev/ttyUSB0:57600 is flown directly" in caplog.text
    # one connection for the whole team: its system ids are learned from what it carries
    (shared,) = relay_specs(["udpin://0.0.0.0:14540"], [0, 1, 2], None).values()
    assert (shared.gcs, shared.gcs_index, shared.system_ids) == (None, 0, frozenset())
