"""MAVLink packets found in a datagram by their headers alone: where each starts and ends, who
sent it, and which system it is addressed to (no payload decoding, no CRC check).

This is what a router needs to pass traffic on and record it: the relay (``relay``) forwards
bytes as they came and writes each packet to its vehicle's .tlog. A MAVLink 1 packet is
``0xFE len seq sysid compid msgid payload crc(2)``; a MAVLink 2 packet is ``0xFD len incompat
compat seq sysid compid msgid(3) payload crc(2) [signature(13)]`` with the payload's trailing
zeros cut (so a target field past the cut is 0). Bytes that are not a packet are skipped to the
next start byte and counted.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass
from typing import Final

from pymavlink.dialects.v20 import ardupilotmega as dialect

MAGIC_V1: Final = 0xFE
MAGIC_V2: Final = 0xFD
HEADER_V1: Final = 6
HEADER_V2: Final = 10
CRC_LEN: Final = 2
SIGNATURE_LEN: Final = 13
INCOMPAT_SIGNED: Final = 0x01


def _target_offsets() -> dict[int, int]:
    """Message id -> byte offset of ``target_system`` in the payload (wire order), for every
    message of the ardupilotmega dialect (a superset of common) that has one."""
    offsets: dict[int, int] = {}
    for msg_id, cls in dialect.mavlink_map.items():
        names = list(cls.ordered_fieldnames)
        if "target_system" not in names:
            continue
        formats = cls.native_format.decode("ascii")[1:]  # past '<'
        offset = 0
        for name, fmt, length in zip(names, formats, cls.array_lengths, strict=True):
            if name == "target_system":
                offsets[msg_id] = offset
                break
            offset += struct.calcsize("<" + fmt) * max(1, length)
    return offsets


#: where ``target_system`` sits in each addressed message's payload
TARGET_OFFSETS: Final = _target_offsets()


@dataclass(frozen=True, slots=True)
class Packet:
    """One MAVLink packet of a datagram: ``data[start:end]``; ``target_system`` 0 when the
    message is broadcast or has no target."""

    start: int
    end: int
    system_id: int
    component_id: int
    msg_id: int
    target_system: int


def split_packets(data: bytes) -> tuple[list[Packet], int]:
    """The whole packets in ``data`` (one datagram), and how many bytes were skipped (garbage,
    or a packet cut short at the end)."""
    packets, skipped, _ = _split(data, stream=False)
    return packets, skipped


def split_stream(data: bytes) -> tuple[list[Packet], int, int]:
    """The whole packets at the start of a byte stream's buffer (TCP, serial), the garbage
    bytes skipped, and where the parsed part ends: a packet cut short at the end is the start
    of the next read, kept."""
    return _split(data, stream=True)


def _split(data: bytes, stream: bool) -> tuple[list[Packet], int, int]:
    packets: list[Packet] = []
    skipped = 0
    i, n = 0, len(data)
    while i < n:
        magic = data[i]
        if magic == MAGIC_V2 and i + HEADER_V2 <= n:
            length = data[i + 1]
            end = i + HEADER_V2 + length + CRC_LEN
            if data[i + 2] & INCOMPAT_SIGNED:
                end += SIGNATURE_LEN
            if end <= n:
                msg_id = data[i + 7] | (data[i + 8] << 8) | (data[i + 9] << 16)
                payload = i + HEADER_V2
                packets.append(
                    Packet(
                        i,
                        end,
                        data[i + 5],
                        data[i + 6],
                        msg_id,
                        _target(data, payload, length, msg_id),
                    )
                )
                i = end
                continue
        elif magic == MAGIC_V1 and i + HEADER_V1 <= n:
            length = data[i + 1]
            end = i + HEADER_V1 + length + CRC_LEN
            if end <= n:
                msg_id = data[i + 5]
                payload = i + HEADER_V1
                packets.append(
                    Packet(
                        i,
                        end,
                        data[i + 3],
                        data[i + 4],
                        msg_id,
                        _target(data, payload, length, msg_id),
                    )
                )
                i = end
                continue
        if stream and magic in (MAGIC_V1, MAGIC_V2) and _may_be_cut_short(data, i):
            return packets, skipped, i  # the rest of this packet has not come yet
        # not a packet here (or one cut short): on to the next start byte
        j = i + 1
        while j < n and data[j] not in (MAGIC_V1, MAGIC_V2):
            j += 1
        skipped += j - i
        i = j
    return packets, skipped, n


def _may_be_cut_short(data: bytes, i: int) -> bool:
    """Whether the packet starting at ``i`` runs past the end of ``data`` (as far as its header,
    or what there is of it, says)."""
    n = len(data)
    header = HEADER_V2 if data[i] == MAGIC_V2 else HEADER_V1
    if i + header > n:
        return True
    end = i + header + data[i + 1] + CRC_LEN
    if data[i] == MAGIC_V2 and data[i + 2] & INCOMPAT_SIGNED:
        end += SIGNATURE_LEN
    return end > n


def _target(data: bytes, payload: int, length: int, msg_id: int) -> int:
    offset = TARGET_OFFSETS.get(msg_id)
    if offset is None or offset >= length:
        return 0  # no target field, or cut off with the payload's trailing zeros
    return data[payload + offset]


#: TIMESYNC: tc1, ts1 (int64 each), then MAVLink 2's extension target_system, target_component
TIMESYNC_ID: Final = 111
TIMESYNC_BASE_LEN: Final = 16
#: CRC_EXTRA of TIMESYNC (extension fields do not change it)
TIMESYNC_CRC_EXTRA: Final = dialect.MAVLink_timesync_message.crc_extra


def broadcast_timesync_answers(data: bytes, packets: list[Packet]) -> bytes:
    """``data`` with every unsigned MAVLink 2 TIMESYNC answer (tc1 != 0) that carries target
    bytes turned into a broadcast (the target bytes cut, the CRC made again); ``data`` itself
    when there is none.

    PX4 v1.16 answers a TIMESYNC request with its target fields uninitialised
    (mavlink_timesync.cpp fills only tc1 and ts1), so a MAVLink library that knows those
    MAVLink 2 extension fields (MAVSDK's) takes the answer for another system's and drops it.
    An answer goes back to whoever asked on the link anyway; as a broadcast it reaches them.
    A signed packet is left as it is (its signature covers the bytes)."""
    patched: list[tuple[Packet, bytes]] = []
    for p in packets:
        if p.msg_id != TIMESYNC_ID or data[p.start] != MAGIC_V2:
            continue
        if data[p.start + 2] & INCOMPAT_SIGNED or data[p.start + 1] <= TIMESYNC_BASE_LEN:
            continue
        payload = data[p.start + HEADER_V2 : p.start + HEADER_V2 + TIMESYNC_BASE_LEN]
        if payload[:8] == bytes(8):  # tc1 == 0: a request, not an answer
            continue
        header = bytearray(data[p.start : p.start + HEADER_V2])
        header[1] = TIMESYNC_BASE_LEN
        patched.append((p, _with_crc(bytes(header) + payload, TIMESYNC_CRC_EXTRA)))
    if not patched:
        return data
    out, at = bytearray(), 0
    for p, packet in patched:
        out += data[at : p.start] + packet
        at = p.end
    out += data[at:]
    return bytes(out)


def _with_crc(body: bytes, crc_extra: int) -> bytes:
    """A MAVLink packet's bytes (magic to payload) with its X.25 checksum (over all but the
    magic, then ``crc_extra``) appended."""
    crc = 0xFFFF
    for byte in (*body[1:], crc_extra):
        tmp = byte ^ (crc & 0xFF)
        tmp = (tmp ^ (tmp << 4)) & 0xFF
        crc = ((crc >> 8) ^ (tmp << 8) ^ (tmp << 3) ^ (tmp >> 4)) & 0xFFFF
    return body + struct.pack("<H", crc)
