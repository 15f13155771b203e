"""The loopback demo: slave and master as two processes, a touch on each of
several materials, each compared with the same finger touching the
material directly."""

from __future__ import annotations

import logging
import os
import signal
import subprocess
import sys
import time
from contextlib import nullcontext
from dataclasses import dataclass
from pathlib import Path

from telethermal.control.loop import DEFAULT_RATE_HZ
from telethermal.demo.calibration import demo_calibration, path_line
from telethermal.demo.touches import demo_touch
from telethermal.devices.kinds import DeviceKind
from telethermal.errors import TransportError
from telethermal.jsonfile import write_json
from telethermal.physics.scene import with_finger
from telethermal.ports import free_ports
from telethermal.services.admin import call
from telethermal.services.qemu_boards import prepare_firmware
from telethermal.services.viewer import open_view
from telethermal.sim.inprocess import service_sensors
from telethermal.teleop.models import demo_identify
from telethermal.tomltables import toml_str
from telethermal.view.server import ViewServer
from telethermal.wire.keys import generate_link_keys

log = logging.getLogger(__name__)


def write_configs(out: Path, scene: str, identifier: Path, generator: Path, ports, seed: int,
                  rate_hz: float = DEFAULT_RATE_HZ, realtime_priority: int = 0,
                  slave_host: str = "127.0.0.1", security: str = "curve",
                  master_ports: tuple[int, int] | None = None,
                  devices: str = "sim", record_dir: str | Path | None = None,
                  view_port: int = 0, firmware_build: str = "", pad_calibration: str = "",
                  slave_pad_calibration: str = "", time_scale: float = 1.0) -> tuple[Path, Path]:
    """Keys and the two config files. ``ports``: control, stream, and the two
    admin addresses (ports on 127.0.0.1, or ``ipc://`` paths).
    ``master_ports``: where the master connects, if not to the slave itself
    (a fault proxy in between; plain loopback sockets then). ``pad_calibration``:
    the master's (its display's), ``slave_pad_calibration`` the slave's (its pad's).
    ``time_scale``: both services' (their configs')."""
    generate_link_keys(out / "keys")
    control, stream, slave_admin, master_admin = ports

    def admin(where):
        return f"admin_ipc = {toml_str(where)}" if isinstance(where, str) else \
            f"admin_port = {where}"

    common = (f'control_port = {control}\nstream_port = {stream}\nsecurity = "{security}"\n')
    m_control, m_stream = master_ports or (control, stream)
    master_common = (f'control_port = {m_control}\nstream_port = {m_stream}\n'
                     f'security = "{security}"\n')
    slave_keys = 'keys_dir = "keys/slave"\nallowed_dir = "keys/allowed"\n' \
        if security == "curve" else ""
    master_keys = 'keys_dir = "keys/master"\n' if security == "curve" else ""
    slave = out / "slave.toml"
    ident, gen = (os.path.relpath(Path(p).resolve(), out.resolve()) for p in (identifier, generator))
    record = f"record_dir = {toml_str(Path(record_dir).resolve())}\n" if record_dir else ""
    record += f"firmware_build = {toml_str(firmware_build)}\n" if firmware_build else ""
    record += f"time_scale = {float(time_scale)!r}\n" if time_scale != 1.0 else ""
    slave.write_text(f"[slave]\nscene = {toml_str(scene)}\nidentifier = {toml_str(ident)}\n"
                     f'{record}{path_line("pad_calibration", slave_pad_calibration)}'
                     f'generator = {toml_str(gen)}\nseed = {seed}\ndevices = "{devices}"\n'
                     f'{admin(slave_admin)}\n\n[transport]\nbind_host = "{slave_host}"\n'
                     f'{common}{slave_keys}')
    master = out / "master.toml"
    master.write_text(f'[master]\nscene = {toml_str(scene)}\nrate_hz = {rate_hz}\nseed = {seed}\n'
                      f'realtime_priority = {realtime_priority}\ndevices = "{devices}"\n{record}'
                      f'view_port = {view_port}\n'
                      + path_line("pad_calibration", pad_calibration) +
                      f'{admin(master_admin)}\n\n[transport]\nhost = "{slave_host}"\n'
                      f'{master_common}{master_keys}')
    return slave, master


class Services:
    """Slave and master processes; stopped by SIGTERM on exit."""

    def __init__(self, out: Path, slave_config: Path, master_config: Path,
                 namespaces: tuple[str | None, str | None] = (None, None)):
        self.out = out
        self.procs = {}
        self._logs = {}
        self._args = {}
        for (role, config), ns in zip((("slave", slave_config), ("master", master_config)),
                                      namespaces):
            prefix = ["ip", "netns", "exec", ns] if ns else []
            self._args[role] = prefix + [sys.executable, "-m", "telethermal", role,
                                         "--config", str(config)]
            self.start(role)

    def start(self, role: str) -> None:
        """Start (or restart) one service; its log is appended to."""
        if role in self._logs:
            self._logs[role].close()
        log = self._logs[role] = open(self.out / f"{role}.log", "a")
        self.procs[role] = subprocess.Popen(self._args[role], stdout=log,
                                            stderr=subprocess.STDOUT,
                                            env={**os.environ, "PYTHONUNBUFFERED": "1"})

    def kill(self, role: str) -> int:
        """SIGKILL: a crash, no clean-up of any kind."""
        proc = self.procs[role]
        proc.kill()
        return proc.wait()

    def log_tail(self, role: str, n: int = 15) -> str:
        lines = (self.out / f"{role}.log").read_text().splitlines()
        return "\n".join(lines[-n:])

    def check_running(self):
        for role, proc in self.procs.items():
            if proc.poll() is not None:
                raise TransportError(f"the {role} process exited ({proc.returncode}):\n"
                                     f"{self.log_tail(role)}")

    def stop(self, timeout_s: float = 10.0) -> dict[str, int]:
        codes = {}
        for proc in self.procs.values():
            if proc.poll() is None:
                proc.send_signal(signal.SIGTERM)
        for role, proc in self.procs.items():
            try:
                codes[role] = proc.wait(timeout_s)
            except subprocess.TimeoutExpired:
                proc.kill()
                codes[role] = proc.wait()
        for log in self._logs.values():
            log.close()
        return codes


def wait_connected(services: Services, master_admin: int, timeout_s: float = 90.0) -> dict:
    end = time.monotonic() + timeout_s
    while time.monotonic() < end:
        services.check_running()
        try:
            status = call(master_admin, "status", timeout_s=1.0)
            if status.get("peer_alive") and status.get("session") and \
                    status.get("object_temp_c") is not None:
                return status
        except TransportError:
            pass
        time.sleep(0.2)
    raise TransportError(f"master and slave did not connect within {timeout_s} s:\n"
                         f"{services.log_tail('master')}\n{services.log_tail('slave')}")


def run_demo(out: Path, scene_name: str, identifier_path: Path, generator_path: Path,
             materials, seed: int = 0, contact_s: float = 5.0, echo=print,
             realtime_priority: int = 20, record_dir: Path | None = None,
             view_port: int | None = None, devices: str = "sim", firmware_build: str = "",
             display_calibration: str = "", pad_calibration: str = "",
             rate_hz: float = DEFAULT_RATE_HZ, time_scale: float = 1.0) -> dict:
    """Returns per touch the networked figures and, for the same seeds, the
    in-process session's (``in_process_flux_rms_error_rel``). ``view_port``:
    the live view (``telethermal view``) on that HTTP port, started once the
    services are up and returned, still running, as ``report["view"]``.
    ``rate_hz``: the master's display rate, networked and in process;
    ``time_scale``: the services' (:func:`demo_time_scale`)."""
    from telethermal.physics.scene import load_scene

    from telethermal.ident.registry import load_model
    from telethermal.render.generator import load_generator

    from telethermal.teleop.display_calibration import display_calibration as read_cal
    from telethermal.teleop.display_calibration import modelled_scene

    scene = with_finger(load_scene(scene_name))
    display_cal = read_cal(display_calibration, scene)          # refused before anything runs
    identifier, generator = load_model(identifier_path), load_generator(generator_path)
    from telethermal.control.preconditioning import prepare_policy

    prepare_policy(modelled_scene(scene, display_cal), echo)   # the display's layers
    ports = free_ports(5)
    slave_cfg, master_cfg = write_configs(out, scene_name, identifier_path, generator_path,
                                          ports[:4], seed, rate_hz=rate_hz,
                                          realtime_priority=realtime_priority,
                                          record_dir=record_dir, devices=devices,
                                          view_port=ports[4] if view_port is not None else 0,
                                          firmware_build=firmware_build,
                                          pad_calibration=display_calibration,
                                          slave_pad_calibration=pad_calibration,
                                          time_scale=time_scale)
    services = Services(out, slave_cfg, master_cfg)
    touches = []
    cal = {}
    view = None
    try:
        wait_connected(services, ports[3])
        echo(f"slave and master up as two processes on loopback (CURVE), the display at "
             f"{rate_hz:g} Hz" +
             ("; each on its emulated devices (boards on ptys, CAN drivers on virtual "
              "buses), read through the drivers" if devices == "emulated" else "") +
             ("; their boards the firmware on emulated STM32F405s (QEMU)"
              if devices == "qemu" else "") +
             (f"; their clocks {time_scale:g} times slower than the machine's (time_scale)"
              if time_scale != 1.0 else ""))
        cal = call(ports[2], "status").get("thermometer_calibration") or {}
        if cal.get("calibrated"):
            echo(f"slave's object thermometer calibrated against its pad at "
                 f"{len(cal['points'])} temperatures: offset {cal['offset_k']:+.3f} K, gain "
                 f"{cal['gain']:.4f}, residual {cal['residual_k']:.3f} K")
        else:
            echo(f"slave's object thermometer NOT calibrated: {cal.get('error')}")
        # The in-process touches read the pad through the slave service's
        # instruments and calibration: the same seed, the same touch.
        sensors = service_sensors(scene, seed, cal or None)   # none reported: as at start
        if view_port is not None:
            view = open_view(master_cfg, record_dir, view_port)
            echo(f"view: {view.url}")
        # Each material once, then the first again: the slave remembers what it
        # decided on that object and announces it, so the master renders the
        # repeated touch from its onset (object memory).
        # The in-process touches remember the same way (their own decisions
        # of each material's object, as the slave's memory holds its own).
        plan = [(m, False) for m in materials] + [(materials[0], True)] if materials else []
        decided = {}
        for i, (material, again) in enumerate(plan):
            row, decided[material] = demo_touch(
                scene, material, ports, seed + 1 + i, contact_s, out, identifier, generator,
                again, echo, display_cal, decided.get(material), sensors, rate_hz)
            touches.append(row)
    except BaseException:
        if view is not None:
            view.close()
        raise
    finally:
        codes = services.stop()
    echo(f"services stopped: exit codes slave {codes['slave']}, master {codes['master']}")
    return {"scene": scene.name, "devices": devices, "rate_hz": rate_hz,
            "time_scale": time_scale, "touches": touches,
            "exit_codes": codes,
            "slave_thermometer_calibration": cal,
            "ports": dict(zip(("control", "stream", "slave_admin", "master_admin"), ports)),
            **({"view": view} if view is not None else {})}


#: The demo's materials when none are named (those of them the scene has).
DEMO_MATERIALS = ("aluminium", "plexiglass", "wood")


@dataclass
class DemoResult:
    """What :func:`demo` leaves: its summary (as written to ``demo.json``)
    and the live view, still running, if one was asked for."""

    report: dict
    view: ViewServer | None = None

    @property
    def ok(self) -> bool:
        """Both services stopped with exit code 0."""
        return all(c == 0 for c in self.report["exit_codes"].values())


def demo_materials(scene, materials=None) -> list[str]:
    """``materials`` as given, or those of :data:`DEMO_MATERIALS` the scene
    has (its first three if none)."""
    if materials is not None:
        return list(materials)
    return [m for m in DEMO_MATERIALS if m in scene.materials] or scene.materials[:3]


def _no_progress(_total: int, _what: str):
    return nullcontext(None)


def _demo_models(scene, out: Path, seed: int, echo, progress, status,
                 method: str | None = None, calibration=None) -> None:
    """The demo's databases (and plot), identifier (``calibration``: its pad's), generator."""
    from telethermal.data.dataset import load_dataset
    from telethermal.data.generate import generate_databases
    from telethermal.data.plots import plot_datasets
    from telethermal.render.generator import NetworkGenerator, save_generator

    start = time.perf_counter()
    with progress(2, "generating") as advance:
        summary = generate_databases(scene, out / "databases", seed=seed, overwrite=True,
                                     progress=advance)
    echo(f"databases in {time.perf_counter() - start:.1f} s: "
         + ", ".join(f"{k} {v['trials']} trials" for k, v in summary["datasets"].items()))
    echo(f"plot: {plot_datasets(out / 'databases', out / 'databases.png')}")
    demo_identify(scene, out, seed, echo, method, calibration)
    with status("training the flux generator on database 2"):
        generator = NetworkGenerator().fit(load_dataset(out / "databases" / "finger"))
    save_generator(generator, out / "generator.npz")


def demo_time_scale(devices: str, rate_hz: float, sample_rate_hz: float,
                    time_scale: float | None = None) -> float:
    """The services' ``time_scale``: ``time_scale`` if given (checked as the
    configs check it); else 1, and on QEMU's cores what their UARTs need
    (:func:`~telethermal.services.qemu_boards.qemu_time_scale`)."""
    from telethermal.services.config import check_config_time_scale
    from telethermal.services.qemu_boards import qemu_time_scale

    if time_scale is None:
        return qemu_time_scale(rate_hz, sample_rate_hz) if devices == "qemu" else 1.0
    return check_config_time_scale(time_scale, DeviceKind(devices))


def demo(out: str | Path, scene_name: str = "fingertip-7", materials=None, seed: int = 0,
         contact_s: float = 5.0, record_dir: str | Path | None = None,
         view_port: int | None = None, devices: str = "sim", json_path=None, echo=print,
         progress=_no_progress, status=nullcontext, method: str | None = None,
         calibration: str = "", rate_hz: float = DEFAULT_RATE_HZ,
         time_scale: float | None = None) -> DemoResult:
    """``telethermal demo``: the scene's databases, an identifier and a flux
    generator trained on them, then slave and master as two processes on
    loopback and a touch on each material (:func:`run_demo`); the summary
    goes to ``json_path`` (default ``out/demo.json``). ``echo`` takes each
    line to show; ``progress(total, what)`` and ``status(text)`` are context
    managers held around the long steps (the first yields a callable taking
    a step's label); ``method``: the identifier's (default: ``teleop.models.
    default_method``); ``calibration``: a file (``demo_calibration``'s);
    ``rate_hz``: the master's display rate; ``time_scale``: the services'
    (None: :func:`demo_time_scale`'s)."""
    from telethermal.physics.scene import describe_models, load_scene

    out = Path(out)
    scene = with_finger(load_scene(scene_name))
    time_scale = demo_time_scale(devices, rate_hz, scene.sample_rate_hz, time_scale)
    firmware = prepare_firmware(out, devices, echo)         # qemu: what is missing, at once
    echo(f"scene {scene.name}: {scene.description.splitlines()[0]}")
    for side, material, choice in describe_models(scene):
        echo(f"  {side:6s} on {material:10s} {choice.describe()}")
    cal = demo_calibration(scene, out, seed, echo, status, calibration)
    _demo_models(scene, out, seed, echo, progress, status, method, cal and cal.pad)
    report = run_demo(out, scene_name, out / "identifier.npz", out / "generator.npz",
                      demo_materials(scene, materials), seed=seed, contact_s=contact_s,
                      echo=echo, record_dir=Path(record_dir) if record_dir else None,
                      view_port=view_port, devices=devices, firmware_build=firmware,
                      display_calibration=cal.display_path if cal else "",
                      pad_calibration=cal.pad_path if cal else "", rate_hz=rate_hz,
                      time_scale=time_scale)
    report |= {"calibration": cal.summary()} if cal else {}
    view = report.pop("view", None)
    path = write_json(json_path or out / "demo.json", report)
    echo(f"touch plots: {out}/touch-*.png; summary: {path}")
    if record_dir:
        files = sorted(Path(record_dir).glob("*.mcap"))
        echo(f"recordings: {', '.join(str(f) for f in files)} "
             f"(telethermal replay FILE --out DIR [--touch N])")
    return DemoResult(report, view)
