"""The services' boards as the reference firmware on emulated STM32F405s
(``devices = "qemu"``, processor in the loop): the images built once when
the service starts (in its ``firmware_build`` folder, or a temporary one),
their cores started then and stopped when the service stops.

* the master: the display's sensor board and Peltier driver
  (:class:`~telethermal.devices.qemu_display.QemuDisplay`), restarted from
  reset for each touch, as the emulated display's boards are new each touch;
* the slave: its sensing pad's version-2 board and active pad driver
  (:class:`~telethermal.devices.qemu_slave_pad.QemuSlavePad`), for the
  service's whole run, as its emulated devices are.
"""

from __future__ import annotations

import logging

from telethermal.devices.kinds import DeviceKind

log = logging.getLogger(__name__)

#: What QEMU's emulated UART takes per byte received, of the machine's time:
#: one turn of QEMU's main loop (about 0.1 ms on a loaded 2-core host, with
#: or without ``-icount``; firmware/README.md, "Processor in the loop").
UART_BYTE_S = 1e-4
#: The bytes the cores take in a period on its critical path: the display's
#: (its sample line, then the command after the frame came back: about 45
#: and 22, the measurement line beside them on the other core) and the
#: slave's (its version-2 sample line).
DISPLAY_PERIOD_BYTES = 70
SLAVE_SAMPLE_BYTES = 80
#: The share of a period the cores' bytes may take in the machine's time:
#: the rest is the services' own work and the host's (a 2-core host runs
#: four cores and two services).
BYTES_SHARE = 0.4


def qemu_time_scale(rate_hz: float, sample_rate_hz: float) -> float:
    """The ``time_scale`` at which QEMU's UARTs carry each side's period in
    :data:`BYTES_SHARE` of it (at least 1), rounded up to a whole number."""
    import math

    need = max(DISPLAY_PERIOD_BYTES * rate_hz, SLAVE_SAMPLE_BYTES * sample_rate_hz) * \
        UART_BYTE_S / BYTES_SHARE
    return float(max(1, math.ceil(need - 1e-9)))


def display_boards(config) -> dict:
    """The master's display options for :func:`~telethermal.devices.display.open_display`:
    ``{"boards": QemuBoards}`` with ``devices = "qemu"`` (built and started
    now; DeviceError naming what is missing), else ``{}``."""
    if config.devices != DeviceKind.QEMU:
        return {}
    from telethermal.devices import qemu
    from telethermal.devices.qemu_display import NAMES

    boards = qemu.QemuBoards(NAMES, config.firmware_build,
                             purpose="the master's devices = 'qemu'",
                             time_scale=config.time_scale)
    log.info("display boards on QEMU: %s", ", ".join(
        f"{name} (pid {core.proc.pid})" for name, core in boards.cores.items()))
    return {"boards": boards}


def close_boards(options: dict) -> None:
    """Stop the cores :func:`display_boards` started (none: nothing)."""
    boards = options.pop("boards", None)
    if boards is not None:
        boards.close()
        log.info("display boards on QEMU stopped")


def prepare_firmware(out, devices: str, echo=print) -> str:
    """``telethermal demo --devices qemu``: what is missing named at once
    (DeviceError with the apt packages), then the images built in
    ``out/firmware`` for both services (their ``firmware_build``); "" for
    other kinds."""
    if devices != DeviceKind.QEMU:
        return ""
    from pathlib import Path

    from telethermal.devices import qemu

    qemu.require("telethermal demo --devices qemu")
    build = Path(out).resolve() / "firmware"
    images = qemu.build_images(build)
    echo(f"firmware built for the STM32F405 in {build}: " + ", ".join(sorted(images)))
    return str(build)
