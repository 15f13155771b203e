"""``telethermal demo --devices qemu`` without QEMU or the cross toolchain
fails at once, before any database or model is made, naming each missing
part with the apt package that provides it; a service configured with
``devices = "qemu"`` refuses to start the same way."""

import pytest

from telethermal.cli import main
from telethermal.devices import qemu
from telethermal.devices.board import DeviceError

GONE = [("qemu-system-arm", "qemu-system-arm"),
        ("picolibc for arm-none-eabi", "picolibc-arm-none-eabi")]


def test_demo_on_qemu_without_the_tools_fails_before_anything_is_computed(
        monkeypatch, tmp_path, capsys):
    from telethermal.demo import run as demo

    monkeypatch.setattr(qemu, "missing", lambda: GONE)
    built = []
    monkeypatch.setattr(qemu, "build_images", lambda *a, **k: built.append(a))
    monkeypatch.setattr(demo, "_demo_models", lambda *a, **k: pytest.fail("models were made"))
    code = main(["demo", "--devices", "qemu", "--materials", "wood",
                 "--out", str(tmp_path / "demo")])
    out = " ".join(capsys.readouterr().err.split())      # the console's lines joined
    assert code == 2 and not built
    assert "telethermal demo --devices qemu needs" in out
    assert "apt-get install qemu-system-arm" in out
    assert "apt-get install picolibc-arm-none-eabi" in out
    assert not (tmp_path / "demo" / "databases").exists()


def test_a_service_on_qemu_without_the_tools_names_them(monkeypatch):
    from types import SimpleNamespace

    from telethermal.devices.kinds import DeviceKind
    from telethermal.services.qemu_boards import display_boards

    monkeypatch.setattr(qemu, "missing", lambda: GONE[:1])
    with pytest.raises(DeviceError, match=r"master's devices = 'qemu' needs qemu-system-arm "
                                          r"\(apt-get install qemu-system-arm\)"):
        display_boards(SimpleNamespace(devices=DeviceKind.QEMU, firmware_build="",
                                       time_scale=1.0))
    assert display_boards(SimpleNamespace(devices=DeviceKind.EMULATED)) == {}


def test_the_service_configs_accept_qemu_and_its_build_folder(tmp_path):
    from telethermal.services.config import load_config

    path = tmp_path / "master.toml"
    path.write_text('[master]\ndevices = "qemu"\nfirmware_build = "fw"\n'
                    '[transport]\nsecurity = "plain"\n')
    config = load_config(path, "master")
    assert config.devices == "qemu" and config.firmware_build == str(tmp_path / "fw")
