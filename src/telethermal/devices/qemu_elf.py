"""What the cross toolchain says of a built image
(:func:`telethermal.devices.qemu.build_images`): its sizes and its symbols."""

from __future__ import annotations

import subprocess
from pathlib import Path

from telethermal.devices.board import DeviceError


def image_size(elf: str | Path) -> dict[str, int]:
    """``arm-none-eabi-size`` of an image: text, data, bss in bytes; flash
    = text + data (the initial values live in flash), ram = data + bss (the
    4 KB stack reserved by the linker script is not counted)."""
    try:
        done = subprocess.run(["arm-none-eabi-size", str(elf)], capture_output=True, text=True,
                              check=True, timeout=60)
        text, data, bss = (int(v) for v in done.stdout.splitlines()[1].split()[:3])
    except (OSError, subprocess.SubprocessError, IndexError, ValueError) as exc:
        said = (getattr(exc, "stderr", None) or "").strip()[-500:]
        exists = Path(elf).is_file()
        raise DeviceError(f"arm-none-eabi-size {elf}: no size read ({exc}"
                          f"{'; it said: ' + said if said else ''}"
                          f"{'' if exists else '; the image is not there'})") from exc
    return {"text": text, "data": data, "bss": bss, "flash": text + data, "ram": data + bss}


def symbols(elf: str | Path) -> dict[str, int]:
    """The image's symbols (``arm-none-eabi-nm``): name -> address."""
    done = subprocess.run(["arm-none-eabi-nm", str(elf)], capture_output=True, text=True,
                          check=True)
    out = {}
    for line in done.stdout.splitlines():
        parts = line.split()
        if len(parts) == 3:
            out[parts[2]] = int(parts[0], 16)
    return out
