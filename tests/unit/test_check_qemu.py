"""``telethermal check --devices qemu``: what the processor in the loop
needs, each missing part named with its Debian package, and the firmware
built (the build itself is tested in tests/integration/test_firmware_qemu.py)."""


from telethermal.cli import main
from telethermal.devices import qemu
from telethermal.services.preflight import qemu_findings


def test_each_missing_part_is_named_with_its_apt_package(monkeypatch, capsys):
    monkeypatch.setattr(qemu, "missing", lambda: [
        ("qemu-system-arm", "qemu-system-arm"), ("arm-none-eabi-gcc", "gcc-arm-none-eabi")])
    findings = qemu_findings()
    assert [f.ok for f in findings] == [False, False]
    assert findings[0].fix == "apt-get install qemu-system-arm"
    assert findings[1].fix == "apt-get install gcc-arm-none-eabi"
    assert main(["check", "--devices", "qemu"]) == 1
    out = capsys.readouterr().out
    assert "PROBLEM  arm-none-eabi-gcc: not installed" in out and "2 problems" in out


def test_firmware_sources_missing_are_named(monkeypatch, tmp_path):
    monkeypatch.setattr(qemu, "missing", lambda: [])
    monkeypatch.setattr(qemu, "FIRMWARE", tmp_path / "firmware")
    findings = qemu_findings()
    assert findings[0].ok and not findings[-1].ok
    assert "no firmware sources" in findings[-1].what and "source checkout" in findings[-1].fix


def test_a_failing_build_is_a_problem_with_the_compilers_words(monkeypatch, tmp_path):
    from telethermal.devices.board import DeviceError

    (tmp_path / "Makefile").write_text("all:\n\tfalse\n")
    monkeypatch.setattr(qemu, "missing", lambda: [])
    monkeypatch.setattr(qemu, "FIRMWARE", tmp_path)

    def fail(build):
        raise DeviceError("the STM32F405 build failed:\nhal.c:1: error: nope")
    monkeypatch.setattr(qemu, "build_images", fail)
    findings = qemu_findings()
    assert not findings[-1].ok and "hal.c:1: error: nope" in findings[-1].what


def test_check_without_a_config_or_devices_says_what_to_give(capsys):
    assert main(["check"]) == 2
    err = capsys.readouterr().err
    assert "--config FILE" in err and "--devices qemu" in err


def test_a_build_that_hangs_or_a_size_that_cannot_be_read_is_a_problem(monkeypatch, tmp_path):
    """The build's timeout, or arm-none-eabi-size failing or printing
    nothing, are DeviceErrors naming what failed: a PROBLEM line, never a
    traceback out of telethermal check."""
    import subprocess

    (tmp_path / "Makefile").write_text("all:\n")
    monkeypatch.setattr(qemu, "missing", lambda: [])
    monkeypatch.setattr(qemu, "FIRMWARE", tmp_path)

    def hangs(*a, **kw):
        raise subprocess.TimeoutExpired(a[0], 300)
    monkeypatch.setattr(qemu.subprocess, "run", hangs)
    findings = qemu_findings()
    assert not findings[-1].ok and "did not run to its end" in findings[-1].what
    monkeypatch.setattr(qemu.subprocess, "run", lambda *a, **kw: subprocess.CompletedProcess(
        a[0], 0, stdout="", stderr=""))
    findings = qemu_findings()
    assert not findings[-1].ok and "no size read" in findings[-1].what


def test_a_build_holds_its_folders_lock_while_make_runs(monkeypatch, tmp_path):
    """Two services sharing a build folder never run make in it at once:
    while make runs, the folder's lock cannot be taken."""
    import fcntl
    import subprocess

    seen = []

    def fake_make(argv, **kw):
        with open(tmp_path / ".build.lock", "w") as other:
            try:
                fcntl.flock(other, fcntl.LOCK_EX | fcntl.LOCK_NB)
                seen.append("free")
            except BlockingIOError:
                seen.append("held")
        return subprocess.CompletedProcess(argv, 0, "", "")

    monkeypatch.setattr(qemu.subprocess, "run", fake_make)
    images = qemu.build_images(tmp_path)
    assert seen == ["held"]
    assert images["tt_peltier"] == tmp_path.resolve() / "stm32f405" / "tt_peltier.elf"
    with open(tmp_path / ".build.lock", "w") as after:            # released after
        fcntl.flock(after, fcntl.LOCK_EX | fcntl.LOCK_NB)


def test_qemu_dies_with_its_parent_through_setpriv_or_says_it_cannot(monkeypatch, caplog):
    monkeypatch.setattr(qemu.shutil, "which", lambda name: f"/usr/bin/{name}")
    assert qemu._dying_with_parent(["qemu", "-M", "x"]) == [
        "/usr/bin/setpriv", "--pdeathsig", "KILL", "--", "qemu", "-M", "x"]
    monkeypatch.setattr(qemu.shutil, "which", lambda name: None)
    with caplog.at_level("WARNING"):
        assert qemu._dying_with_parent(["qemu"]) == ["qemu"]
    assert "setpriv not found (apt-get install util-linux)" in caplog.text
