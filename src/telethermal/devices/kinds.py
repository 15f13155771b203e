"""The kinds of devices a service runs on, validated in one place."""

from __future__ import annotations

from enum import StrEnum


class DeviceKind(StrEnum):
    #: The simulator directly.
    SIM = "sim"
    #: The simulator behind emulated boards (a pty, a virtual CAN bus), read
    #: and commanded through the real drivers.
    EMULATED = "emulated"
    #: The real boards at ``board_url`` and ``can_bus``.
    HARDWARE = "hardware"
    #: The reference firmware as the boards, on emulated STM32F405 cores
    #: (qemu-system-arm), the simulator behind them: processor in the loop.
    QEMU = "qemu"


#: The kinds the services run (``device_kind``).
SERVICE_KINDS = (DeviceKind.SIM, DeviceKind.EMULATED, DeviceKind.HARDWARE, DeviceKind.QEMU)


def parse_device_kind(value: str, kinds: tuple = tuple(DeviceKind)) -> DeviceKind:
    """``value`` as one of ``kinds``; ``ValueError`` naming them."""
    kind = next((k for k in kinds if k.value == value), None)
    if kind is None:
        *first, last = (repr(k.value) for k in kinds)
        raise ValueError(f"devices must be {', '.join(first)} or {last}, got {value!r}")
    return kind


def device_kind(value: str, board_url: str, can_bus: str,
                example_tty: str = "/dev/ttyUSB0") -> DeviceKind:
    """A service config's kind: one of :data:`SERVICE_KINDS`, and hardware
    with both its ports."""
    kind = parse_device_kind(value, SERVICE_KINDS)
    if kind == DeviceKind.HARDWARE and not (board_url and can_bus):
        raise ValueError(f"devices = 'hardware' needs board_url (e.g. {example_tty}) and "
                         "can_bus (e.g. socketcan:can0)")
    return kind
