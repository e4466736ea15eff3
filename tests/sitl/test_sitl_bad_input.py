"""Garbage, unknown messages, commands for other systems and a 10,000-packet flood: the simulator
drops and counts them, keeps time, and every vehicle still answers."""

import asyncio
import math
import random
import socket

import pytest
from pymavlink.dialects.v20 import common as mavlink

from tests.support.sitl_fixtures import RawClient, running_sim, sim_config

ACCEPTED = mavlink.MAV_RESULT_ACCEPTED


def _bad_packets(rng: random.Random, other_ids: list[int]) -> list[bytes]:
    """One of each kind of bad input, from a stranger (system 77); the commands and setpoints
    are addressed to ``other_ids``: systems other than the receiving vehicle."""
    enc = mavlink.MAVLink(None, 77, 1)

    def pack(msg: mavlink.MAVLink_message) -> bytes:
        return bytes(msg.pack(enc))

    packets: list[bytes] = []
    packets.append(bytes(rng.randrange(256) for _ in range(rng.randrange(1, 300))))  # garbage
    beat = bytearray(pack(mavlink.MAVLink_heartbeat_message(6, 8, 0, 0, 0, 3)))
    packets.append(bytes(beat[: rng.randrange(1, len(beat))]))  # truncated
    corrupt = bytearray(beat)
    corrupt[-1] ^= 0xFF
    packets.append(bytes(corrupt))  # bad checksum
    unknown = bytearray(beat)
    unknown[7:10] = b"\x34\x12\x0f"  # message id 0x0f1234: not in any dialect
    packets.append(bytes(unknown))
    other = rng.choice(other_ids)
    packets.append(
        pack(
            mavlink.MAVLink_command_long_message(
                other, 1, mavlink.MAV_CMD_COMPONENT_ARM_DISARM, 0, 1.0, 0, 0, 0, 0, 0, 0
            )
        )
    )
    nan_setpoint = mavlink.MAVLink_set_position_target_local_ned_message(
        0,
        other,
        1,
        mavlink.MAV_FRAME_LOCAL_NED,
        0,
        math.nan,
        math.inf,
        0.0,
        math.nan,
        -math.inf,
        0.0,
        0.0,
        0.0,
        0.0,
        math.nan,
        0.0,
    )
    packets.append(pack(nan_setpoint))
    packets.append(pack(mavlink.MAVLink_param_request_list_message(other, 1)))  # not handled
    packets.append(
        pack(
            mavlink.MAVLink_command_long_message(
                other, 1, mavlink.MAV_CMD_DO_SET_MODE, 0, math.inf, math.nan, -1e30, 0, 0, 0, 0
            )
        )
    )
    return packets


@pytest.mark.slow
async def test_bad_input_and_a_10000_packet_burst_neither_crash_nor_stall():
    config = sim_config(3, speedup=10.0, takeoff="launch")
    rng = random.Random(4)
    async with running_sim(config) as sim:
        clients = [RawClient(e.gcs_port) for e in sim.endpoints]
        for client in clients:
            await client.__aenter__()
        try:
            for client in clients:
                await client.heartbeat()
            ports = [e.local_port for e in sim.endpoints]
            others = [[99, *(j for j in (1, 2, 3) if j != k + 1)] for k in range(3)]
            kinds = [_bad_packets(rng, others[k]) for k in range(3)]
            packets = [
                kinds[i % 3][(i // 3) % len(kinds[0])] if i % 7 else _bad_packets(rng, [99])[0]
                for i in range(10_000)
            ]

            def blast() -> int:
                # from another thread, as fast as the socket takes them, while the sim runs
                with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as fuzz:
                    for i, packet in enumerate(packets):
                        fuzz.sendto(packet, ("127.0.0.1", ports[i % 3]))
                return len(packets)

            t_before = sim.time_s
            assert await asyncio.to_thread(blast) == 10_000

            # every vehicle still answers, and simulated time still runs
            for sysid, client in enumerate(clients, start=1):
                start = len(client.inbox.messages)
                result = await client.command(
                    mavlink.MAV_CMD_REQUEST_MESSAGE, 148.0, target_system=sysid, timeout_s=2.0
                )
                assert result == ACCEPTED
                await client.wait_for(
                    lambda m: m.get_type() == "AUTOPILOT_VERSION", start=start, timeout_s=2.0
                )
                await client.wait_for(lambda m: m.get_type() == "HEARTBEAT", timeout_s=2.0)
            await asyncio.wait_for(sim.wait_until(sim.time_s + 2.0), timeout=2.0)
            assert sim.time_s > t_before
        finally:
            for client in clients:
                await client.__aexit__()

    truth = sim.truth()
    assert not any(v.armed for v in truth.vehicles), "a command for another system was obeyed"
    assert all(v.mode == "hold" for v in truth.vehicles)
    total = sim.stats_total()
    assert total.packets_in > 2_000  # the rest the kernel dropped: the sim cannot see those
    assert total.garbled > 0
    assert total.unknown > 0
    assert total.other_system > 0
    assert total.handler_errors == 0
