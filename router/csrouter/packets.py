"""Sizes of IP packets as the router counts them: IP bytes and TCP/UDP payload bytes."""

from __future__ import annotations

import struct
from dataclasses import dataclass

TCP = 6
UDP = 17
UDP_HEADER = 8
IPV6_HEADER = 40
# enough of a packet to read the IPv4 header (at most 60 bytes) and TCP's data offset
HEADER_COPY_BYTES = 128


@dataclass(frozen=True)
class PacketSize:
    """What one packet costs: its whole IP length and the payload charged to the cap."""

    ip_bytes: int
    payload_bytes: int


def measure(header: bytes) -> PacketSize:
    """Return a packet's IP length and payload from its first bytes (IPv4 or IPv6).

    Payload is the TCP/UDP payload. A non-first IPv4 fragment carries only payload. Other
    protocols (ICMP, ...) are charged everything after the IP header, so no traffic crosses
    the router uncharged. Malformed headers are charged their whole length as payload.
    """
    if len(header) < 1:
        return PacketSize(0, 0)
    version = header[0] >> 4
    if version == 4:
        return _measure_ipv4(header)
    if version == 6:
        return _measure_ipv6(header)
    return PacketSize(len(header), len(header))


def _measure_ipv4(header: bytes) -> PacketSize:
    if len(header) < 20:
        return PacketSize(len(header), len(header))
    header_length = (header[0] & 0x0F) * 4
    total_length, fragment = struct.unpack_from("!H2xH", header, 2)
    if header_length < 20 or total_length < header_length:
        return PacketSize(total_length, total_length)
    ip_payload = total_length - header_length
    if fragment & 0x1FFF:  # not the first fragment: no transport header in it
        return PacketSize(total_length, ip_payload)
    return PacketSize(
        total_length, _transport_payload(header, header[9], header_length, ip_payload)
    )


def _measure_ipv6(header: bytes) -> PacketSize:
    if len(header) < IPV6_HEADER:
        return PacketSize(len(header), len(header))
    (payload_length,) = struct.unpack_from("!H", header, 4)
    total_length = IPV6_HEADER + payload_length
    # extension headers are not walked: anything but a direct TCP/UDP header is all payload
    return PacketSize(
        total_length, _transport_payload(header, header[6], IPV6_HEADER, payload_length)
    )


def _transport_payload(header: bytes, protocol: int, offset: int, ip_payload: int) -> int:
    if protocol == UDP:
        return max(ip_payload - UDP_HEADER, 0)
    if protocol == TCP and len(header) > offset + 12:
        data_offset = (header[offset + 12] >> 4) * 4
        return max(ip_payload - data_offset, 0)
    return ip_payload
