"""Service configuration files (TOML), read with errors that name the file
and the key. Relative paths are relative to the file's own folder."""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from pathlib import Path

from telethermal.control.loop import DEFAULT_RATE_HZ, check_time_scale
from telethermal.devices.kinds import DeviceKind, device_kind
from telethermal.errors import TelethermalError
from telethermal.tomltables import read_toml, table_values
from telethermal.wire.transport import TransportConfig


class ConfigError(TelethermalError):
    """A service configuration file that cannot be used."""


def _check_ports(config, names: tuple[str, ...], off_ok: tuple[str, ...] = ()) -> None:
    """Each of ``names`` a TCP port, 1-65535 (0 too for ``off_ok``: off)."""
    from telethermal.ports import port_problem

    for name in names:
        value = getattr(config, name)
        why = port_problem(value, "off" if name in off_ok else None)
        if why:
            raise ConfigError(f"{name} = {value!r}: {why}")


def parse_cpus(text: str) -> set[int]:
    """A config's ``cpus``: core numbers and ranges, comma-separated ("1",
    "2,3", "2-3", as taskset takes them); empty: none (any core)."""
    cores: set[int] = set()
    for part in (p.strip() for p in str(text).split(",")) if text else ():
        lo, _, hi = part.partition("-")
        if not (lo.isdigit() and (hi.isdigit() or not _)) or (hi and int(hi) < int(lo)):
            raise ConfigError(f"cpus = {text!r}: core numbers and ranges, e.g. '1', '2,3' or "
                              "'2-3' (empty: any)")
        cores.update(range(int(lo), int(hi or lo) + 1))
    return cores


def _devices(config, example_tty: str) -> DeviceKind:
    """The config's device kind, validated (the one place it is)."""
    try:
        return device_kind(config.devices, config.board_url, config.can_bus, example_tty)
    except ValueError as exc:
        raise ConfigError(str(exc)) from None


def check_config_time_scale(time_scale, devices: DeviceKind) -> float:
    """A ``time_scale`` for ``devices``, validated: a number from 1 up; other
    than 1 only with devices that wait for the service (the simulator;
    QEMU's cores, whose millisecond the bridge stretches as much)."""
    from telethermal.devices.qemu import MAX_TIME_SCALE as QEMU_MAX

    scale = check_time_scale(time_scale, ConfigError, "time_scale")
    if scale != 1.0 and devices not in (DeviceKind.SIM, DeviceKind.QEMU):
        raise ConfigError(f"time_scale = {time_scale!r} with devices = {devices.value!r}: "
                          "only the simulator's and QEMU's devices run on a slowed clock "
                          "(emulated boards and hardware keep the machine's time): use 1")
    if devices == DeviceKind.QEMU and scale > QEMU_MAX:
        raise ConfigError(f"time_scale = {time_scale!r} with devices = 'qemu': the cores "
                          f"stretch their millisecond at most {QEMU_MAX:g} times (SysTick's 24 "
                          "bits at 168 MHz)")
    return scale


#: The slowest display loop a master runs, Hz: two of its commands inside
#: the Peltier driver's 100 ms watchdog (proto/CAN.md), so that one late
#: period does not disable the element.
MIN_RATE_HZ = 20.0
MIN_RATE_WHY = "two commands inside the Peltier driver's 100 ms watchdog"


@dataclass
class SlaveConfig:
    scene: str = "fingertip-7"
    identifier: str = ""            # saved identifier; empty: train on the scene (seed)
    generator: str = ""             # saved generator; empty: train on the scene (seed)
    seed: int = 0
    place: str = ""                 # object under the pad at start; empty: the scene's first
    admin_port: int = 5570
    admin_ipc: str = ""             # an ipc:// path instead of the port
    record_dir: str = ""            # record every touch here (one MCAP file per run)
    #: The sensing pad's devices: "sim" (the simulator directly), "emulated"
    #: (the simulator behind an emulated sensor board, frame version 2, on a
    #: pty and the active pad's driver on a virtual CAN bus, read and
    #: commanded through the real drivers; a Peltier pad only) or "hardware"
    #: (the board at ``board_url`` and the pad's driver on ``can_bus``; no
    #: simulator: ``place`` only names the object for the reports); "qemu":
    #: as "emulated" with the firmware images on emulated STM32F405s as the
    #: boards (firmware/README.md, "Processor in the loop").
    devices: DeviceKind = DeviceKind.SIM           # a string is read as its kind
    board_url: str = ""             # pyserial URL of the slave's sensor board (hardware)
    can_bus: str = ""               # interface:channel of its active pad's driver (hardware)
    calibration: str = ""           # the board's calibration TOML; empty: the defaults
    #: devices = "qemu": the firmware's build folder (make's, incremental);
    #: empty: built in a temporary folder at start.
    firmware_build: str = ""
    #: The sensing pad's model calibration (``telethermal calibrate pad``,
    #: docs/calibration.md); empty: the scene's design values.
    pad_calibration: str = ""
    #: How many of the machine's seconds one second of the service lasts (1:
    #: real time): for boards slower than real time (devices = "qemu":
    #: QEMU's UARTs, firmware/README.md), whose plant waits for them and
    #: whose cores' millisecond is stretched as much. Both services of a
    #: session must run on the same (the services cannot tell; ``telethermal
    #: admin status`` says when they differ); the simulator's and QEMU's
    #: devices only.
    time_scale: float = 1.0
    transport: TransportConfig = field(default_factory=TransportConfig)

    def __post_init__(self):
        _check_ports(self, ("admin_port",))
        self.devices = _devices(self, "/dev/ttyUSB1")
        self.time_scale = check_config_time_scale(self.time_scale, self.devices)


@dataclass
class MasterConfig:
    scene: str = "fingertip-7"
    rate_hz: float = DEFAULT_RATE_HZ
    before: str = "prior"
    #: Where the display's pad idles before a touch: "policy" (the scene's
    #: idle policy: pre-conditioned for the material the slave expects, the
    #: minimax idle for an unknown object) or "object" (its temperature).
    #: With "policy" the master makes the scene's policy ready at start
    #: (a scene with none shipped or cached: minutes, once, then cached).
    idle: str = "policy"
    seed: int = 0
    admin_port: int = 5571
    admin_ipc: str = ""
    #: SCHED_FIFO priority of the display loop (1-99); 0 leaves the default
    #: scheduler. Needs CAP_SYS_NICE (root); refused with a warning otherwise.
    realtime_priority: int = 0
    #: CPU cores the display loop may run on (empty: any).
    cpus: str = ""
    #: The display's devices: "sim" (the simulator directly), "emulated"
    #: (the simulator behind an emulated sensor board on a pty and an emulated
    #: Peltier driver on a CAN bus, read through the real drivers), or
    #: "hardware" (the sensor board at ``board_url`` and the Peltier driver on
    #: ``can_bus``: the display loop runs all the time and the operator's
    #: force starts each touch); "qemu": as "emulated" with the firmware
    #: images on emulated STM32F405s as the boards, restarted each touch.
    devices: DeviceKind = DeviceKind.SIM           # a string is read as its kind
    board_url: str = ""             # pyserial URL of the sensor board (hardware)
    can_bus: str = ""               # interface:channel of the Peltier driver (hardware)
    calibration: str = ""           # the board's calibration TOML; empty: the defaults
    firmware_build: str = ""        # devices = "qemu": as the slave's
    #: The display pad's calibration: the ``[display]`` table of a
    #: calibration file (``telethermal calibrate display``, docs/calibration.md):
    #: its flux and junction sensor lags replace the scene's in the
    #: controllers; empty: the scene's.
    pad_calibration: str = ""
    #: The finger's temperature before contact (hardware: no IR channel yet).
    finger_temp_c: float = 33.0
    #: Folder to record every touch to (one MCAP file per run); empty: no recording.
    record_dir: str = ""
    #: The view stream (a PUB socket on 127.0.0.1, read by ``telethermal
    #: view``); 0: off.
    view_port: int = 0
    #: As the slave's (:attr:`SlaveConfig.time_scale`): the same in both.
    time_scale: float = 1.0
    transport: TransportConfig = field(default_factory=TransportConfig)

    def __post_init__(self):
        import math
        _check_ports(self, ("admin_port", "view_port"), off_ok=("view_port",))
        if not (isinstance(self.rate_hz, (int, float)) and math.isfinite(self.rate_hz)
                and MIN_RATE_HZ <= self.rate_hz <= 10000):
            raise ConfigError(f"rate_hz = {self.rate_hz!r}: the display loop's rate, from "
                              f"{MIN_RATE_HZ:g} Hz ({MIN_RATE_WHY}) up to 10000 Hz")
        parse_cpus(self.cpus)
        if isinstance(self.realtime_priority, bool) or not isinstance(
                self.realtime_priority, int) or not 0 <= self.realtime_priority <= 99:
            raise ConfigError(f"realtime_priority = {self.realtime_priority!r}: 1-99 "
                              "(SCHED_FIFO), or 0 for the default scheduler")
        self.devices = _devices(self, "/dev/ttyUSB0")
        self.time_scale = check_config_time_scale(self.time_scale, self.devices)


def load_config(path: str | Path, role: str):
    """Read ``[<role>]``, ``[transport]`` of a service config file."""
    path = Path(path)
    data = read_toml(path, "config file", ConfigError)
    extra = set(data) - {role, "transport"}
    if extra:
        raise ConfigError(f"{path}: unknown section(s) {', '.join(sorted(extra))}; expected "
                          f"[{role}] and [transport]")
    cls = SlaveConfig if role == "slave" else MasterConfig
    # table_values names the file and the table itself; the class's own
    # checks do not know them: only their errors get the prefix.
    values = table_values(cls, data.get(role, {}), f"{path} [{role}]", ConfigError,
                          exclude=("transport",))
    try:
        config = cls(**values)
    except ConfigError as exc:
        raise ConfigError(f"{path} [{role}]: {exc}") from exc
    transport = TransportConfig(**table_values(TransportConfig, data.get("transport", {}),
                                        f"{path} [transport]"))
    base = path.resolve().parent
    for key in ("keys_dir", "allowed_dir"):
        value = getattr(transport, key)
        if value and not Path(value).is_absolute():
            transport = replace(transport, **{key: str(base / value)})
    for key in ("identifier", "generator", "record_dir", "calibration", "pad_calibration",
                "firmware_build"):
        value = getattr(config, key, "")
        if value and not Path(value).is_absolute():
            setattr(config, key, str(base / value))
    config.transport = transport
    try:
        transport.validate(role)
    except TelethermalError as exc:
        raise ConfigError(f"{path} [transport]: {exc}") from exc
    return config
