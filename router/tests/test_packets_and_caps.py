"""Packet sizes and cap decisions, from bytes built here (no hosts)."""

from __future__ import annotations

import struct

import pytest
from csrouter.meter import DirectionMeter, Totals
from csrouter.packets import PacketSize, measure


def ipv4(protocol: int, transport: bytes, payload_length: int, *, fragment: int = 0) -> bytes:
    """Return the first bytes of an IPv4 packet (20-byte header) whose payload is this long."""
    total = 20 + len(transport) + payload_length
    header = struct.pack("!BBHHHBBH4s4s", 0x45, 0, total, 1, fragment, 64, protocol, 0,
                         bytes([10, 8, 0, 2]), bytes([10, 0, 0, 51]))  # fmt: skip
    return header + transport


def tcp_header(options: int = 0) -> bytes:
    """Return a TCP header with `options` bytes of options (data offset set accordingly)."""
    offset_words = (20 + options) // 4
    return struct.pack("!HHIIBBHHH", 1, 2, 0, 0, offset_words << 4, 0x18, 0, 0, 0) + bytes(options)


def test_udp_payload_excludes_ip_and_udp_headers() -> None:
    assert measure(ipv4(17, bytes(8), 1000)) == PacketSize(ip_bytes=1028, payload_bytes=1000)


def test_tcp_payload_excludes_options_and_a_bare_ack_is_free() -> None:
    assert measure(ipv4(6, tcp_header(12), 500)) == PacketSize(552, 500)
    assert measure(ipv4(6, tcp_header(12), 0)) == PacketSize(52, 0)


def test_icmp_and_other_protocols_are_charged_their_whole_ip_payload() -> None:
    assert measure(ipv4(1, bytes(8), 56)) == PacketSize(84, 64)


def test_fragments_add_up_to_the_datagram_payload() -> None:
    first = measure(ipv4(17, bytes(8), 1472, fragment=0x2000))  # more fragments
    rest = measure(ipv4(17, b"", 528, fragment=185))  # offset 1480 bytes, no UDP header
    assert first.payload_bytes + rest.payload_bytes == 2000


def test_ipv6_udp_and_malformed_headers() -> None:
    ipv6 = struct.pack("!IHBB16s16s", 6 << 28, 8 + 100, 17, 64, bytes(16), bytes(16)) + bytes(8)
    assert measure(ipv6) == PacketSize(148, 100)
    assert measure(b"\x45\x00") == PacketSize(2, 2)  # truncated: everything is charged
    assert measure(b"") == PacketSize(0, 0)


def test_without_a_cap_everything_is_accepted_and_counted() -> None:
    meter = DirectionMeter()
    assert all(meter.admit(PacketSize(1028, 1000)) for _ in range(5))
    assert meter.accepted == Totals(5, 5140, 5000) and meter.remaining_bits is None


def test_a_packet_is_accepted_only_if_its_whole_payload_fits() -> None:
    meter = DirectionMeter(cap_bits=8 * 2500)
    assert meter.admit(PacketSize(1028, 1000)) and meter.admit(PacketSize(1028, 1000))
    assert not meter.admit(PacketSize(1028, 1000))  # 1000 > 500 left
    assert meter.spent and meter.remaining_bits == 8 * 500


def test_once_spent_even_a_packet_that_would_fit_is_dropped() -> None:
    meter = DirectionMeter(cap_bits=8 * 1500)
    meter.admit(PacketSize(1028, 1000))
    meter.admit(PacketSize(1028, 1000))  # spends the direction
    assert not meter.admit(PacketSize(28, 0)) and not meter.admit(PacketSize(128, 100))
    assert meter.dropped == Totals(3, 1184, 1100)


def test_a_cap_filled_exactly_still_passes_empty_packets_until_one_does_not_fit() -> None:
    meter = DirectionMeter(cap_bits=8 * 1000)
    assert meter.admit(PacketSize(1028, 1000)) and meter.remaining_bits == 0
    assert meter.admit(PacketSize(40, 0)) and not meter.spent
    assert not meter.admit(PacketSize(41, 1)) and meter.spent


def test_a_zero_cap_blocks_any_payload() -> None:
    meter = DirectionMeter(cap_bits=0)
    assert not meter.admit(PacketSize(29, 1))


def test_the_second_counts_restart_and_snapshots_restore() -> None:
    meter = DirectionMeter(cap_bits=80_000)
    meter.admit(PacketSize(1028, 1000))
    accepted, dropped = meter.take_second()
    assert accepted == Totals(1, 1028, 1000) and dropped == Totals()
    assert meter.take_second() == (Totals(), Totals())
    restored = DirectionMeter.restore(meter.snapshot())
    assert restored.accepted == meter.accepted and restored.remaining_bits == 72_000


def test_negative_caps_are_refused() -> None:
    with pytest.raises(ValueError, match="negative"):
        DirectionMeter(cap_bits=-1)
