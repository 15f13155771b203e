"""The operator's commands against real service processes on loopback:
`telethermal admin` (status, place, touch, lift, report, send),
`telethermal check`, `telethermal models`, `telethermal keys`; and a master
whose key was missing from the slave's allowed/ coming in, unrestarted,
once the key is copied."""

import json
import math
import shutil
import time
from pathlib import Path

import pytest

from telethermal.cli import main
from telethermal.physics.scene import load_scene, with_finger
from telethermal.services.admin import call
from telethermal.demo.run import Services, wait_connected, write_configs
from telethermal.ports import free_ports
from telethermal.teleop.models import write_models
from telethermal.wire.handshake import key_file_fingerprint
from telethermal.wire.sockets import DIAGNOSE_AFTER_S

SCENE = with_finger(load_scene("fingertip-7"))


@pytest.fixture(scope="module")
def models(tmp_path_factory):
    folder = tmp_path_factory.mktemp("models")
    write_models(folder, SCENE.name, seed=0)
    return folder / "identifier.npz", folder / "generator.npz"


def admin(ports, *argv, capsys):
    """Exit code and what was printed (the replies on stdout, errors on stderr)."""
    code = main(["admin", "--slave", str(ports[2]), "--master", str(ports[3]), *argv])
    captured = capsys.readouterr()
    return code, captured.out + captured.err


def _until(admin_port, done, guard_s: float = 60.0) -> bool:
    """Whether the service's status came to ``done`` (a hang guard of
    ``guard_s``: how soon is a real-clock figure, not asserted)."""
    deadline = time.monotonic() + guard_s
    while time.monotonic() < deadline:
        if done(call(admin_port, "status")):
            return True
        time.sleep(0.05)
    return False


def test_models_writes_loadable_files_and_their_checksums(models):
    folder = models[0].parent
    sums = (folder / "SHA256SUMS").read_text().splitlines()
    assert [line.split("  ")[1] for line in sums] == ["identifier.npz", "generator.npz"]
    import hashlib
    for line in sums:
        digest, name = line.split("  ")
        assert hashlib.sha256((folder / name).read_bytes()).hexdigest() == digest


def test_a_bench_given_the_models_folder_runs_on_what_it_would_train(models, trained_models):
    """`make bench` trains once (`telethermal models`) and gives the folder
    to its session benches (--models): the files are, byte for byte, what
    a bench trains by itself (the scene's databases, seed 0), so its
    sessions are the same; the JSON's `models` says which files."""
    import hashlib

    from telethermal.bench.models import TRAINING_SEED, bench_models
    folder = models[0].parent
    own = trained_models.files(SCENE, TRAINING_SEED)
    assert [p.read_bytes() for p in own] == [p.read_bytes() for p in models]
    _, _, provenance = bench_models(SCENE, folder)
    assert provenance == {"trained": False, "scene": SCENE.name, "files": {
        p.name: hashlib.sha256(p.read_bytes()).hexdigest() for p in models}}


def test_a_bench_refuses_a_models_folder_it_cannot_trust(models, tmp_path):
    """Each refusal names the folder and what is wrong, before any session
    runs: no such folder, a file missing, no SHA256SUMS, a file not matching
    it, and models trained on another scene or on a dataset (their
    checksums right)."""
    from telethermal.bench.models import bench_models
    from telethermal.errors import BenchError
    from telethermal.ident.registry import load_model
    from telethermal.teleop.models import write_sums

    with pytest.raises(BenchError, match="no such folder"):
        bench_models(SCENE, tmp_path / "none")
    for case in ("missing", "no sums", "changed", "other scene", "a dataset"):
        folder = tmp_path / case
        shutil.copytree(models[0].parent, folder)
        if case == "missing":
            (folder / "generator.npz").unlink()
            match = "no generator.npz"
        elif case == "no sums":
            (folder / "SHA256SUMS").unlink()
            match = "no SHA256SUMS"
        elif case == "changed":
            with open(folder / "identifier.npz", "ab") as f:
                f.write(b"\0")
            match = "identifier.npz does not match SHA256SUMS"
        else:
            other = load_model(folder / "identifier.npz")
            if case == "other scene":
                other.scene_ = "gripper-case-II"
                match = "trained on gripper-case-II, this bench runs fingertip-7"
            else:
                other.training_digests_ = ["0" * 64]
                match = r"trained on a dataset \(models --data\)"
            other.save(folder / "identifier.npz")
            write_sums(folder, [folder / "identifier.npz", folder / "generator.npz"])
        with pytest.raises(BenchError, match=match) as err:
            bench_models(SCENE, folder)
        assert str(folder) in str(err.value)


@pytest.mark.slow          # over 10 s here: make test-all and CI run it
def test_admin_operates_a_session_and_reports_the_touch(tmp_path, models, capsys):
    ports = free_ports(4)
    slave_cfg, master_cfg = write_configs(tmp_path, SCENE.name, *models, ports, 0)
    services = Services(tmp_path, slave_cfg, master_cfg)
    try:
        wait_connected(services, ports[3])
        code, out = admin(ports, "status", "--wait", "10", capsys=capsys)
        assert code == 0 and "slave: idle, peer alive" in out and "master: idle, peer alive" \
            in out
        code, out = admin(ports, "place", "wood", "--seed", "1", capsys=capsys)
        assert code == 0 and out.startswith("placed wood")
        # The truth comes from the slave's admin socket (reachable here).
        code, out = admin(ports, "touch", "--contact-s", "1.5", "--seed", "1", capsys=capsys)
        assert code == 0, out
        assert "against direct contact with wood" in out
        touch_out = out
        code, out = admin(ports, "--json", "report", capsys=capsys)
        report = json.loads(out)
        assert "trace" not in report and report["slave"]["material"] == "wood"
        # What the master was told is what the slave decided.
        assert report["identified"] == report["slave"]["identified"] != "unknown"
        assert f"identified {report['identified']}" in touch_out
        # The report holds the touch's figures against direct contact. Their
        # size is a real-clock outcome (this touch ran on the services' real
        # clock; a stalled master integrates the stall open loop): the
        # rendering's accuracy is asserted on the simulated clock
        # (test_session, test_sim_network) and counted by `bench faults`.
        assert math.isfinite(report["direct"]["flux_rms_error_rel_first_s"])
        # A touch lifted early is shorter than asked: lifted once the master's
        # contact has begun (its status says so), not after a sleep.
        code, out = admin(ports, "touch", "--contact-s", "20", "--no-wait", capsys=capsys)
        assert code == 0 and "started" in out
        assert _until(ports[3], lambda s: s["state"] in ("touching", "rendering")), \
            "the contact never began"
        code, out = admin(ports, "lift", capsys=capsys)
        assert code == 0 and "lifted after" in out
        lifted_s = float(out.split("lifted after ")[1].split(" s")[0])
        assert lifted_s < 20
        assert _until(ports[3], lambda s: s["state"] == "idle"), "the lifted touch never ended"
        report = call(ports[3], "report")
        assert report["contact_id"] == 2 and report["contact_s"] == pytest.approx(lifted_s, abs=0.01)
        assert report["contact_s"] > 0                       # lifted after the contact began
        # Any request by name; an unknown one is an error naming the commands.
        code, out = admin(ports, "send", "slave", "status", capsys=capsys)
        assert code == 0 and json.loads(out)["material"] == "wood"
        code, out = admin(ports, "send", "master", "nonsense", capsys=capsys)
        assert code == 2 and "unknown command 'nonsense'" in " ".join(out.split())
        # Object memory: the first touch decided wood on the scene's object "wood".
        code, out = admin(ports, "place", "wood", "--seed", "2", capsys=capsys)
        assert code == 0 and "object wood: remembered as wood" in out
        code, out = admin(ports, "place", "wood", "--object-id", "cup-9", capsys=capsys)
        assert code == 0 and "object cup-9: nothing remembered of it" in out
        code, out = admin(ports, "status", "slave", capsys=capsys)
        assert code == 0 and "object cup-9; memory: wood: wood (" in out
        code, out = admin(ports, "send", "slave", "forget", capsys=capsys)
        assert code == 0 and json.loads(out)["memory"] == {}
    finally:
        codes = services.stop()
    assert codes == {"slave": 0, "master": 0}
    for role in ("slave", "master"):
        assert "touch over contact_id=1" in (tmp_path / f"{role}.log").read_text()
    assert "flux error" in (tmp_path / "master.log").read_text()


@pytest.mark.slow          # over 10 s here: make test-all and CI run it
def test_a_missing_master_key_is_shown_by_admin_status_and_fixed_without_restart(
        tmp_path, models, capsys):
    ports = free_ports(4)
    slave_cfg, master_cfg = write_configs(tmp_path, SCENE.name, *models, ports, 0)
    allowed_key = tmp_path / "keys" / "allowed" / "master.key"
    allowed_key.unlink()
    services = Services(tmp_path, slave_cfg, master_cfg)
    master_pid = services.procs["master"].pid
    try:
        # The services load their models; until the slave listens the master
        # names a refused port ("address"), then at once the refused key.
        deadline = time.monotonic() + 60
        status = {}
        while time.monotonic() < deadline and \
                (status.get("diagnosis") or {}).get("likely") != "key":
            services.check_running()
            try:
                status = call(ports[3], "status", timeout_s=1.0)
            except Exception:
                pass
            time.sleep(0.1)
        d = status["diagnosis"]
        fp = key_file_fingerprint(tmp_path / "keys" / "master" / "master.key")
        assert d["likely"] == "key" and fp in d["fix"]
        code, out = admin(ports, "status", capsys=capsys)
        assert "likely: this master's key is not allowed" in out
        assert f"last rejected CURVE key {fp} from 127.0.0.1" in out
        assert call(ports[2], "status")["counters"]["curve_rejected"] >= 1
        # (--session-wait 5: the refusal names what the master's status says,
        # which already holds the diagnosis; the default waits 30 s for it.)
        code, out = admin(ports, "touch", "--session-wait", "5", capsys=capsys)
        assert code == 2                                          # refused, with the cause
        assert "key is not allowed" in " ".join(out.split())
        shutil.copy(tmp_path / "keys" / "master" / "master.key", allowed_key)
        # Back within one reconnect interval plus the hello and the session
        # config; the bound is left to wait_connected's timeout (no wall-clock
        # figure asserted: this machine is shared).
        wait_connected(services, ports[3], timeout_s=60)          # a hang guard
        assert services.procs["master"].pid == master_pid and \
            services.procs["master"].poll() is None
        assert call(ports[3], "status")["diagnosis"] is None
    finally:
        services.stop()
    assert "rejected CURVE key " + fp in (tmp_path / "slave.log").read_text()
    assert "not allowed" in (tmp_path / "master.log").read_text()


def test_check_names_each_problem_with_its_fix(tmp_path, models, capsys):
    ports = free_ports(4)
    slave_cfg, master_cfg = write_configs(tmp_path, SCENE.name, *models, ports, 0)
    assert main(["check", "--config", str(slave_cfg)]) == 0
    assert "ready: no problem found" in capsys.readouterr().out
    # A master with no slave running: both ports refused, each with a fix.
    assert main(["check", "--config", str(master_cfg), "--timeout-s", "1"]) == 1
    out = capsys.readouterr().out
    assert out.count("connection refused") == 2 and "fix: start `telethermal slave`" in out
    # Break the slave's set-up three ways.
    (tmp_path / "keys" / "allowed" / "master.key").unlink()
    copy = tmp_path / "models-copy"
    shutil.copytree(models[0].parent, copy)
    with open(copy / "generator.npz", "ab") as f:
        f.write(b"x")                                    # a copy gone wrong
    def slave_config(name, identifier, bind_host):
        path = tmp_path / name
        path.write_text(f'[slave]\nidentifier = "{identifier}"\n'
                        f'generator = "models-copy/generator.npz"\nadmin_port = {ports[2]}\n'
                        f'[transport]\nbind_host = "{bind_host}"\ncontrol_port = {ports[0]}\n'
                        f'stream_port = {ports[1]}\nkeys_dir = "keys/slave"\n'
                        f'allowed_dir = "keys/allowed"\n')
        return str(path)

    assert main(["check", "--config", slave_config("broken.toml", "nowhere/identifier.npz",
                                                   "192.0.2.77")]) == 1
    out = capsys.readouterr().out
    assert "holds no public key" in out and "copy each master's keys/master.key" in out
    assert "no such model file" in out and "telethermal models" in out
    assert "192.0.2.77: not an address of this host" in out
    assert main(["check", "--config", slave_config("broken2.toml",
                                                   "models-copy/identifier.npz",
                                                   "127.0.0.1")]) == 1
    assert "generator.npz: does not match" in capsys.readouterr().out


def test_keys_makes_the_allowed_folder_for_a_slave(tmp_path, capsys):
    assert main(["keys", "--out", str(tmp_path / "keys"), "--name", "slave"]) == 0
    out = capsys.readouterr().out
    assert (tmp_path / "keys" / "allowed").is_dir()
    assert key_file_fingerprint(tmp_path / "keys" / "slave.key") in out
    assert main(["keys", "--out", str(tmp_path / "m"), "--name", "master"]) == 0
    assert not (tmp_path / "m" / "allowed").exists()


def test_a_slave_without_its_model_file_says_how_to_make_it(tmp_path, capsys):
    cfg = tmp_path / "slave.toml"
    cfg.write_text('[slave]\nidentifier = "identifier.npz"\n\n[transport]\nsecurity = "plain"\n')
    assert main(["slave", "--config", str(cfg)]) == 2
    out = " ".join(capsys.readouterr().err.split())
    assert "no such model file" in out and "telethermal models" in out


def test_diagnosis_of_a_silent_drop_is_the_firewall():
    from telethermal.wire.handshake import HandshakeWatch, diagnose
    watch = HandshakeWatch("tcp://10.0.0.1:5560", attempts=1)   # SYNs never answered
    d = diagnose(watch, DIAGNOSE_AFTER_S, "sha256:0", "keys")
    assert d["likely"] == "firewall" and "slave.nft" in d["fix"]


@pytest.mark.slow          # over 10 s here: make test-all and CI run it
def test_a_firewall_that_drops_the_master_is_named_then_fixed_in_namespaces(tmp_path, models):
    # The slave's rule set admits another address than the master's: the
    # master's SYNs are dropped, and it names the firewall. With the right
    # address the session comes up, the master unrestarted.
    import os
    import subprocess

    from telethermal.netns import Namespaces
    reason = Namespaces.why_not() or (None if shutil.which("nft") else "nft is not installed")
    if reason:
        if os.environ.get("TELETHERMAL_REQUIRE_NETNS") == "1":
            pytest.fail(f"TELETHERMAL_REQUIRE_NETNS=1 but {reason}")
        pytest.skip(reason)
    rules = Path(__file__).resolve().parents[2] / "deploy" / "two-host" / "slave.nft"
    admin_at = (f"ipc://{tmp_path}/slave-admin", f"ipc://{tmp_path}/master-admin")
    with Namespaces("tf") as ns:
        def firewall(master_ip):
            subprocess.run(["ip", "netns", "exec", ns.names[0], "nft", "-D",
                            f"MASTER_IP={master_ip}", "-f", str(rules)], check=True)

        firewall("10.231.0.99")
        ports = (5560, 5561, *admin_at)             # the rule set's ports
        slave_cfg, master_cfg = write_configs(tmp_path, SCENE.name, *models, ports, 0,
                                              slave_host=ns.addresses[0])
        services = Services(tmp_path, slave_cfg, master_cfg, namespaces=ns.names)
        try:
            deadline = time.monotonic() + 60
            status = {}
            while time.monotonic() < deadline and not status.get("diagnosis"):
                services.check_running()
                try:
                    status = call(admin_at[1], "status", timeout_s=1.0)
                except Exception:
                    pass
                time.sleep(0.1)
            d = status["diagnosis"]
            assert d["likely"] == "firewall" and "slave.nft" in d["fix"]
            waited_s = float(d["problem"].split(" after ")[1].split(" s ")[0])
            assert waited_s >= DIAGNOSE_AFTER_S          # never named before it is due
            firewall(ns.addresses[1])
            wait_connected(services, admin_at[1], timeout_s=60)     # a hang guard
            # The mechanism, not a wall-clock figure: while nothing answered,
            # the master made a new socket every UNANSWERED_S (so the opened
            # port is found within that, not after the kernel's SYN back-off).
            assert call(admin_at[1], "status")["counters"]["sockets_recreated"] >= 1
        finally:
            codes = services.stop()
    assert codes == {"slave": 0, "master": 0}
