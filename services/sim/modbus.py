"""Modbus/TCP as the simulated crane controller answers it (pure): MBAP frames, the four
function codes the register map documents, and the exceptions of the Modbus Application
Protocol Specification V1.1b3 (§6.3, 6.4, 6.6, 6.12 and §7).

Only the documented registers exist. Per the spec's state diagrams, a request is checked in
this order: function code (01 illegal function for any other, with the function byte
FC | 0x80), quantity and length (03 illegal data value), every address it touches (02 illegal
data address). A request for another unit gets 0B (gateway target device failed to respond),
as a gateway answers for a device that is not behind it, rather than silence.
"""

from __future__ import annotations

import struct
from collections.abc import Iterator
from dataclasses import dataclass
from typing import Protocol

READ_HOLDING, READ_INPUT, WRITE_SINGLE, WRITE_MULTIPLE = 3, 4, 6, 16
ILLEGAL_FUNCTION, ILLEGAL_ADDRESS, ILLEGAL_VALUE, DEVICE_FAILURE = 1, 2, 3, 4
GATEWAY_TARGET_FAILED = 0x0B
MAX_READ, MAX_WRITE = 125, 123  # registers in one request (§6.3, §6.12)
MBAP = struct.Struct(">HHHB")  # transaction id, protocol id (0), length, unit id
MAX_LENGTH = 254  # unit id + a PDU of at most 253 bytes


class Registers(Protocol):
    """The registers a device has, and what reading and writing them does."""

    holding: frozenset[int]
    inputs: frozenset[int]

    def read_holding(self, address: int, count: int) -> list[int]: ...
    def read_input(self, address: int, count: int) -> list[int]: ...
    def write(self, address: int, values: list[int]) -> None: ...


class BadFrame(ValueError):
    """Not Modbus/TCP: the connection is closed (the spec's answer to a broken MBAP header)."""


@dataclass(frozen=True)
class Request:
    transaction: int
    unit: int
    pdu: bytes


def exception(function: int, code: int) -> bytes:
    return bytes([(function | 0x80) & 0xFF, code])


def answer(pdu: bytes, registers: Registers) -> bytes:
    """The response PDU to one request PDU."""
    function = pdu[0] if pdu else 0
    if function in (READ_HOLDING, READ_INPUT):
        return _read(function, pdu, registers)
    if function == WRITE_SINGLE:
        if len(pdu) != 5:
            return exception(function, ILLEGAL_VALUE)
        address, value = struct.unpack(">HH", pdu[1:5])
        if address not in registers.holding:
            return exception(function, ILLEGAL_ADDRESS)
        registers.write(address, [value])
        return pdu  # the echo
    if function == WRITE_MULTIPLE:
        if len(pdu) < 6:
            return exception(function, ILLEGAL_VALUE)
        address, count, size = struct.unpack(">HHB", pdu[1:6])
        if not 1 <= count <= MAX_WRITE or size != 2 * count or len(pdu) != 6 + size:
            return exception(function, ILLEGAL_VALUE)
        if not _all_in(address, count, registers.holding):
            return exception(function, ILLEGAL_ADDRESS)
        registers.write(address, list(struct.unpack(f">{count}H", pdu[6:])))
        return pdu[:5]
    return exception(function, ILLEGAL_FUNCTION)


def _read(function: int, pdu: bytes, registers: Registers) -> bytes:
    if len(pdu) != 5:
        return exception(function, ILLEGAL_VALUE)
    address, count = struct.unpack(">HH", pdu[1:5])
    if not 1 <= count <= MAX_READ:
        return exception(function, ILLEGAL_VALUE)
    exists = registers.holding if function == READ_HOLDING else registers.inputs
    if not _all_in(address, count, exists):
        return exception(function, ILLEGAL_ADDRESS)
    read = registers.read_holding if function == READ_HOLDING else registers.read_input
    values = read(address, count)
    return bytes([function, 2 * count]) + struct.pack(f">{count}H", *values)


def _all_in(address: int, count: int, exists: frozenset[int]) -> bool:
    return all(a in exists for a in range(address, address + count))


def split_requests(buffer: bytearray) -> Iterator[Request]:
    """The whole requests at the head of ``buffer`` (removed from it); BadFrame for a header
    that is not Modbus/TCP."""
    while len(buffer) >= MBAP.size:
        transaction, protocol, length, unit = MBAP.unpack_from(buffer)
        if protocol != 0 or not 2 <= length <= MAX_LENGTH:
            raise BadFrame(f"protocol id {protocol}, length {length}")
        end = 6 + length
        if len(buffer) < end:
            return
        pdu = bytes(buffer[MBAP.size:end])
        del buffer[:end]
        yield Request(transaction, unit, pdu)


def frame(request: Request, pdu: bytes) -> bytes:
    """The response ADU: ``pdu`` under the request's transaction and unit."""
    return MBAP.pack(request.transaction, 0, len(pdu) + 1, request.unit) + pdu
