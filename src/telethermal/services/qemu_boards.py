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


def display_boards(config) -> dict:
    """The master's display options for :func:`~telethermal.devices.display.open_display`:
    ``{"boards": QemuBoards}`` with ``devices = "qemu"`` (built and started
    now; DeviceError naming what is missing), else ``{}``."""
    if config.devices != DeviceKind.QEMU:
        return {}
    from telethermal.devices import qemu
    from telethermal.devices.qemu_display import NAMES

    boards = qemu.QemuBoards(NAMES, config.firmware_build,
                             purpose="the master's devices = 'qemu'")
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
