"""The admin client's pieces that need no service: arguments, addresses,
and the lines a person reads."""

import pytest

from telethermal.services.admin_client import (AdminError, describe_status, describe_touch,
                                               parse_args, resolve)


def test_key_value_arguments_are_json_where_they_parse():
    assert parse_args(["seed=3", "contact_s=1.5", "material=wood", "wait=false",
                       "ids=[1,2]"]) == {"seed": 3, "contact_s": 1.5, "material": "wood",
                                         "wait": False, "ids": [1, 2]}
    with pytest.raises(AdminError, match="key=value"):
        parse_args(["seed"])


def test_addresses_are_ports_ipc_paths_or_config_files(tmp_path):
    assert resolve(None, "slave") == 5570 and resolve(None, "master") == 5571
    assert resolve("6000", "slave") == 6000
    assert resolve("ipc:///run/x", "master") == "ipc:///run/x"
    cfg = tmp_path / "m.toml"
    cfg.write_text('[master]\nadmin_port = 6123\n[transport]\nsecurity = "plain"\n')
    assert resolve(str(cfg), "master") == 6123
    # HOST:PORT, what a person types first: this host's, or a clear error.
    assert resolve("127.0.0.1:15571", "master") == 15571
    assert resolve("localhost:6001", "slave") == 6001
    assert resolve("tcp://127.0.0.1:6002", "slave") == 6002
    with pytest.raises(AdminError, match=r"--master 10\.1\.2\.3:5571: .*127\.0\.0\.1 only.*"
                                         r"ssh -N -L 5571:127\.0\.0\.1:5571 10\.1\.2\.3"):
        resolve("10.1.2.3:5571", "master")
    with pytest.raises(AdminError, match="expected tcp://127.0.0.1:PORT"):
        resolve("tcp://127.0.0.1", "slave")


def test_status_lines_name_the_problem_and_every_other_cause():
    d = {"problem": "no session after 3.0 s", "likely": "firewall", "fix": "open the ports",
         "causes": ["check the address", "open the ports", "copy the key"]}
    lines = describe_status({"role": "master", "state": "idle", "peer_alive": False,
                             "rtt_s": None, "counters": {"resent": 0, "sockets_recreated": 2},
                             "diagnosis": d, "slave": "10.0.0.1:5560"})
    assert lines[0] == "master: idle, peer silent, rtt -, slave at 10.0.0.1:5560"
    assert lines[1] == "  counters: sockets_recreated 2"
    assert "  likely: open the ports" in lines
    assert [x for x in lines if x.startswith("  or: ")] == ["  or: check the address",
                                                          "  or: copy the key"]
    slave = describe_status({"role": "slave", "state": "idle", "peer_alive": False,
                             "counters": {"curve_rejected": 4}, "material": "wood",
                             "last_rejected_key": {"fingerprint": "sha256:ab", "address":
                                                   "10.0.0.2"}})
    assert "rejected CURVE key sha256:ab from 10.0.0.2 (4 refusals)" in slave[-1]
    assert "copy its master.key" in slave[-1]


def test_a_touch_without_the_placed_object_says_why_there_are_no_errors():
    lines = describe_touch({"contact_id": 3, "identified": "wood", "decision_time_s": 0.6,
                            "render_start_s": 0.62, "safety_events": 0, "rtt_s": 7.5e-4,
                            "direct": None})
    assert lines[0] == ("touch 3: identified wood (decided at 0.60 s), rendering from 0.62 s, "
                        "safety events 0, rtt 0.75 ms")
    assert "--material and --object-c" in lines[1]


def test_an_unknown_touch_says_why():
    lines = describe_touch({"contact_id": 4, "identified": "unknown",
                            "unknown_reason": "force outside trained range",
                            "decision_time_s": None, "render_start_s": None,
                            "safety_events": 0, "rtt_s": None, "direct": None})
    assert lines[0].startswith("touch 4: identified unknown (force outside trained range; "
                               "no decision)")


def test_a_new_material_touch_says_its_estimate_and_nearest_class():
    """A master of issue 30's revision gives the decision's text; an older
    one gives the label alone, said as it is."""
    result = {"contact_id": 5, "identified": "new material", "decision_time_s": 1.0,
              "render_start_s": None, "safety_events": 0, "rtt_s": None, "direct": None,
              "decision_text": "new material, effusivity 42.4 W s^0.5/(m^2 K) (95 %: 41.6 "
                               "to 43.1), nearest: wood"}
    assert describe_touch(result)[0].startswith(
        "touch 5: identified new material, effusivity 42.4 W s^0.5/(m^2 K) (95 %: 41.6 to "
        "43.1), nearest: wood (decided at 1.00 s)")
    del result["decision_text"]
    assert describe_touch(result)[0].startswith("touch 5: identified new material (decided")


def test_unknown_reason_is_none_only_for_a_name():
    from telethermal.ident.anytime import Estimate, Reason, unknown_reason

    assert unknown_reason(None) == Reason.NO_ESTIMATE
    assert unknown_reason(Estimate(0.1, (0.5, 0.5), "wood", 0.5, False)) == Reason.NO_DECISION
    assert unknown_reason(Estimate(1.0, (0.5, 0.5), "unknown", 0.5, True,
                                   Reason.FORCE_OUTSIDE)) == "force outside trained range"
    assert unknown_reason(Estimate(0.2, (0.0, 1.0), "wood", 1.0, True, Reason.CONFIDENT)) is None
    assert unknown_reason(Estimate(0.2, (0.5, 0.5), "plexiglass|rubber", 0.99, True,
                                   Reason.CONFIDENT_GROUP)) is None


def test_services_on_different_clocks_are_no_live_session(monkeypatch):
    """Each service judges the other's heartbeats and times on its own
    clock (``time_scale``): two scales are said, and the session not live."""
    import telethermal.services.admin_client as ac

    def status(role, scale):
        return {"role": role, "state": "idle", "peer_alive": True, "session": "s",
                "rtt_s": 1e-4, "counters": {}, "time_scale": scale}

    scales = {"slave": 1.0, "master": 9.0}
    monkeypatch.setattr(ac, "request", lambda where, role, cmd, timeout_s: status(
        role, scales[role]))
    poll = ac.poll_status({"slave": 1, "master": 2}, ("slave", "master"))
    assert not poll.live
    assert poll.lines[-1] == ("problem: the services run on different clocks (time_scale: "
                              "slave 1, master 9): give both configs the same time_scale")
    assert poll.lines[2] == "master: idle, peer alive, rtt 0.10 ms, time scale 9"
    scales["slave"] = 9.0
    poll = ac.poll_status({"slave": 1, "master": 2}, ("slave", "master"))
    assert poll.live and not any("different clocks" in line for line in poll.lines)
