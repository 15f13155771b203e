"""The view's pieces without a browser: the master's view stream, the feed's
decimation and fan-out, recordings as series, the HTTP server's answers to
bad recordings."""

import json
import math
import queue
import time
import urllib.error
import urllib.request

import pytest
import zmq

from telethermal.record.recording import Recorder
from telethermal.record.recorder import SessionRecorder
from telethermal.view.stream import BATCH_S, ViewPublisher, skin_estimate_c

BATCH = round(BATCH_S * 1000.0)          # readings per message at 1 kHz
from telethermal.devices.readings import PadSensors
from telethermal.teleop.master import MasterStep, SlaveNews
from telethermal.view.feed import CLIENT_QUEUE, MAX_RATE_HZ, Frames, LiveFeed, _decimated
from telethermal.view.playback import RecordingError, load_playback
from telethermal.view.server import ViewServer
from telethermal.wire.codec import decode

STATE = {"contact_id": 2, "touching": True, "phase": "render", "safe": False,
         "setpoint_w_m2": -900.0, "events": {}, "link": {"stream_lost": 1}, "rtt_s": 0.001,
         "classes": ["a", "b"], "posteriors": [0.25, 0.75], "label": "b", "decided": True,
         "estimate_t_s": 0.5}


def _until(done, what: str, guard_s: float = 30.0) -> None:
    """Wait for ``done()`` (a hang guard: how soon is the machine's load's)."""
    end = time.monotonic() + guard_s
    while not done():
        assert time.monotonic() < end, what
        time.sleep(0.01)


def _subscribed(pub: ViewPublisher, sub) -> None:
    """Until the SUB's subscription has reached the PUB (a PUB drops what it
    sends before: ZeroMQ's slow joiner): probes on the PUB's own socket,
    outside the view stream's numbering, until one arrives, then read up to
    the last one sent (one connection: in order), so none is left before
    the test's messages. A hang guard of 30 s."""
    sent, got = [], None
    end = time.monotonic() + 30.0
    while got is None:
        assert time.monotonic() < end, "the subscription never reached the publisher"
        sent.append(f"probe {len(sent)}".encode())
        pub.sock.send(sent[-1])
        got = sub.recv() if sub.poll(10) else None
    while got != sent[-1]:
        assert sub.poll(30_000), "a probe sent after the subscription was lost"
        got = sub.recv()


@pytest.fixture
def publisher_and_sub():
    pub = ViewPublisher(0, 2000.0)
    sub = zmq.Context.instance().socket(zmq.SUB)
    sub.linger = 0
    sub.setsockopt(zmq.SUBSCRIBE, b"")
    sub.connect(f"tcp://127.0.0.1:{pub.port}")
    _subscribed(pub, sub)
    yield pub, sub
    pub.close()
    sub.close(linger=0)


def test_view_stream_batches_are_protocol_messages(publisher_and_sub):
    pub, sub = publisher_and_sub
    for k in range(2 * BATCH):
        flux = math.nan if k == 5 else -100.0 * k        # a faulty reading: the last kept
        pub.period(10.0 + k / 1000, 1000.0, flux, 30.0 + k / 100, 4.0, lambda: dict(STATE))
    assert sub.poll(2000)
    first = decode(sub.recv())
    assert sub.poll(2000), "the second batch never came"     # a hang guard
    second = decode(sub.recv())
    assert first["kind"] == "measurement_batch" and first["seq"] == 1 and second["seq"] == 2
    assert len(first["flux_w_m2"]) == BATCH and first["t0_s"] == 10.0
    assert first["flux_w_m2"][5] == first["flux_w_m2"][4] and pub.counters["nonfinite"] == 1
    assert first["posteriors"] == [0.25, 0.75] and first["link"] == {"stream_lost": 1}
    # At 200 Hz, the same 20 ms: four readings a message.
    for k in range(4):
        pub.period(20.0 + k / 200, 200.0, -1.0, 30.0, 4.0, lambda: dict(STATE))
    assert sub.poll(2000)
    assert len(decode(sub.recv())["flux_w_m2"]) == 4
    # The skin under the pad: the pad surface less flux / conductance (pad -> finger +).
    assert second["skin_temp_c"] == pytest.approx(
        second["temp_c"][-1] - second["flux_w_m2"][-1] / 2000.0)
    assert skin_estimate_c(30.0, 2000.0, 2000.0) == 29.0


def test_view_stream_idle_state_and_no_skin_out_of_contact(publisher_and_sub):
    pub, sub = publisher_and_sub
    pub.idle(5.0, lambda: {**STATE, "touching": False, "contact_id": 0})
    pub.idle(5.05, lambda: dict(STATE))                 # within 0.1 s: nothing more
    assert sub.poll(2000)
    m = decode(sub.recv())
    assert m["temp_c"] == [] and m["skin_temp_c"] is None and m["phase"] == "render"
    assert not sub.poll(200)


def test_a_touch_s_last_samples_go_out_when_it_ends(publisher_and_sub):
    pub, sub = publisher_and_sub
    for k in range(BATCH + 7):
        pub.period(1.0 + k / 1000, 1000.0, -1.0, 30.0, 4.0, lambda: dict(STATE))
    pub.idle(9.0, lambda: {**STATE, "touching": False})    # the next touch starts later
    assert sub.poll(2000)
    decode(sub.recv())
    assert sub.poll(2000)
    rest = decode(sub.recv())
    assert len(rest["temp_c"]) == 7 and rest["t0_s"] == pytest.approx(1.0 + BATCH / 1000)


def test_a_slow_subscriber_never_blocks_the_publisher():
    pub = ViewPublisher(0, 2000.0, hwm=2)
    sub = zmq.Context.instance().socket(zmq.SUB)
    sub.linger, sub.rcvhwm = 0, 2
    sub.setsockopt(zmq.SUBSCRIBE, b"")
    sub.connect(f"tcp://127.0.0.1:{pub.port}")
    try:
        time.sleep(0.2)
        for k in range(BATCH * 2000):                    # never read
            pub.period(k / 1000, 1000.0, 1.0, 30.0, 4.0, lambda: dict(STATE))
        assert pub.counters["sent"] + pub.counters["dropped"] == 2000
    finally:
        pub.close()
        sub.close(linger=0)


def test_decimation_keeps_at_most_the_view_rate():
    pts = _decimated(100.0, 1000.0, list(range(1000)), 90.0)
    assert len(pts) == int(MAX_RATE_HZ)
    assert pts[0] == [10.0, 0] and pts[1][0] == pytest.approx(10.0 + 1000 / MAX_RATE_HZ / 1000)
    assert len(_decimated(0.0, 50.0, [1.0] * 50, 0.0)) == 50      # slower: every sample


def test_a_full_client_queue_drops_its_oldest_frames():
    frames = Frames()
    q = frames.subscribe()
    for k in range(CLIENT_QUEUE + 10):
        frames.publish({"k": k})
    assert frames.dropped == 10 and q.get_nowait() == {"k": 10}
    frames.unsubscribe(q)
    frames.publish({"k": -1})                             # nobody listening: nothing kept
    assert frames.clients == 0


def test_feed_turns_both_streams_into_frames(publisher_and_sub):
    pub, _ = publisher_and_sub
    slave_pub = zmq.Context.instance().socket(zmq.PUB)
    slave_pub.linger = 0
    port = slave_pub.bind_to_random_port("tcp://127.0.0.1")
    feed = LiveFeed(f"tcp://127.0.0.1:{pub.port}", f"tcp://127.0.0.1:{port}").start()
    q = feed.frames.subscribe()
    from telethermal.wire.codec import encode
    try:
        # Both subscriptions made before the test's messages (slow joiner):
        # on the master's stream a probe the feed counts as invalid, on the
        # slave's a flux setpoint (neither adds to the batches' counts).
        def probe(sock, data, counter):
            sock.send(data)
            return feed.counters[counter] > 0

        _until(lambda: probe(pub.sock, b"probe", "invalid"), "the feed never heard the master")
        setpoint = encode({"kind": "flux_setpoint", "v": 1, "seq": 1, "sent_s": time.monotonic(),
                           "contact_id": 2, "t_since_contact_s": 0.0, "flux_w_m2": 1.0})
        _until(lambda: probe(slave_pub, setpoint, "setpoints"), "the feed never heard the slave")
        now = time.monotonic()
        for k in range(BATCH):
            pub.period(now + k / 1000, 1000.0, -10.0, 30.0, 4.0, lambda: dict(STATE))
        slave_pub.send(encode({"kind": "measurement_batch", "v": 1, "seq": 1, "sent_s": now,
                               "contact_id": 2, "t0_s": now, "rate_hz": 100.0,
                               "flux_w_m2": [5.0] * 10, "temp_c": [29.0] * 10,
                               "force_n": [1.0] * 10}))
        got = {"master": 0, "slave": 0}
        state = None
        end = time.monotonic() + 30                       # a hang guard
        while time.monotonic() < end and not (got["master"] and got["slave"] and state):
            try:
                f = q.get(timeout=0.5)
            except queue.Empty:
                continue
            got = {k: got[k] + f["counts"][k] for k in got}
            state = state or f["state"]
        assert got == {"master": BATCH, "slave": 10}
        assert state["estimate"]["label"] == "b" and state["link"]["stream_lost"] == 1
    finally:
        feed.close()
        slave_pub.close(linger=0)


def _recording(path, cut_at: float | None = None, scene="fingertip-7", start_params=None):
    rec = SessionRecorder(Recorder(path, "master", {"scene": scene}))
    rec.touch_start(100.0, 1, start_params or {})
    news = SlaveNews(24.0)
    for k in range(400):
        if k == 200:
            from telethermal.ident.anytime import Estimate
            news = SlaveNews(24.0, Estimate(0.2, (0.1, 0.9), "b", 0.9, True, "confident"),
                             ("a", "b"))
        rec.period(k / 1000, 1e-3, PadSensors(-500.0, 30.0, 4.0), news,
                   MasterStep(k / 1000, "render", True, -480.0, 25.0, 25.0, False))
    rec.close()
    if cut_at is not None:
        data = path.read_bytes()
        path.write_bytes(data[:int(len(data) * cut_at)])
    return path


def test_playback_series_of_a_recording(tmp_path):
    p = load_playback(_recording(tmp_path / "a.mcap"))
    assert p["counts"]["master"] == 400 and p["truncated"] is None
    assert len(p["series"]["master_temp"]) == 400 * MAX_RATE_HZ // 1000
    assert p["estimates"][-1]["label"] == "b" and p["estimates"][-1]["decided"]
    json.dumps(p, allow_nan=False)                         # what the server sends


def test_playback_of_a_scene_file_not_on_this_machine_uses_what_the_recording_holds(tmp_path):
    """A service's recording made on a lab's scene file holds, at each
    touch's start, the contact conductance its display was given: the view
    plays it without the scene file (it refused: 'cannot be loaded here');
    a recording that holds none, of a scene it cannot load, is still refused."""
    p = load_playback(_recording(tmp_path / "lab.mcap", scene="lab-pad-elsewhere",
                                 start_params={"contact_conductance_w_m2k": 2500.0}))
    assert p["counts"]["master"] == 400
    with pytest.raises(RecordingError, match="cannot be loaded here"):
        load_playback(_recording(tmp_path / "bare.mcap", scene="lab-pad-elsewhere"))


def test_playback_of_a_cut_recording_says_so(tmp_path):
    p = load_playback(_recording(tmp_path / "a.mcap", cut_at=0.7))
    assert p["truncated"] and 0 < p["counts"]["master"] < 400


def test_bad_recordings_get_a_clear_answer_and_the_server_goes_on(tmp_path):
    (tmp_path / "junk.mcap").write_bytes(b"junk")
    _recording(tmp_path / "good.mcap")
    server = ViewServer(0, None, tmp_path).start()
    try:
        for name, status, text in (("junk.mcap", 422, "not a telethermal recording"),
                                   ("nope.mcap", 404, "no recording"),
                                   ("../good.mcap", 404, "no recording")):
            with pytest.raises(urllib.error.HTTPError) as err:
                urllib.request.urlopen(f"{server.url}api/recording?name={name}")
            assert err.value.code == status and text in json.load(err.value)["error"]
        with urllib.request.urlopen(f"{server.url}api/recording?name=good.mcap") as resp:
            assert json.load(resp)["counts"]["master"] == 400
        with urllib.request.urlopen(server.url) as resp:
            assert b"/static/view.js" in resp.read()
    finally:
        server.close()


def test_other_version_is_refused_with_the_file(tmp_path, monkeypatch):
    import telethermal.record.recording as recording
    monkeypatch.setattr(recording, "RECORDING_VERSION", 7)
    path = _recording(tmp_path / "v7.mcap")
    monkeypatch.undo()
    with pytest.raises(RecordingError, match="v7.mcap.*recording version 7"):
        load_playback(path)


def test_an_unknown_on_the_view_stream_carries_its_reason():
    # The master's view batch holds the estimate's reason (an optional field
    # of measurement_batch); the page's state passes it on.
    from telethermal.view.feed import master_state
    from telethermal.wire.codec import encode

    batch = {"kind": "measurement_batch", "v": 1, "seq": 1, "sent_s": 0.0, "contact_id": 2,
             "t0_s": 0.0, "rate_hz": 500.0, "flux_w_m2": [0.0], "temp_c": [30.0],
             "force_n": [8.0], "classes": ["steel", "wood"], "posteriors": [0.5, 0.5],
             "label": "unknown", "decided": True, "estimate_t_s": 1.0,
             "reason": "force outside trained range"}
    state = master_state(decode(encode(batch)))
    assert state["estimate"]["reason"] == "force outside trained range"
    assert "reason" not in decode(encode({k: v for k, v in batch.items() if k != "reason"}))


def test_a_new_material_on_the_view_stream_carries_its_estimate():
    # The master's view batch holds the estimate's effusivity fields (issue
    # 30, optional fields of measurement_batch); the page's state passes
    # them on, and view.js says them beside the label.
    from pathlib import Path

    from telethermal.view.feed import master_state
    from telethermal.wire.codec import encode

    batch = {"kind": "measurement_batch", "v": 1, "seq": 1, "sent_s": 0.0, "contact_id": 2,
             "t0_s": 0.0, "rate_hz": 500.0, "flux_w_m2": [0.0], "temp_c": [30.0],
             "force_n": [8.0], "classes": ["steel", "wood"], "posteriors": [0.0, 1.0],
             "label": "new material", "decided": True, "estimate_t_s": 1.0,
             "reason": "new material", "effusivity_w_s05_m2k": 42.5,
             "effusivity_lo_w_s05_m2k": 41.5, "effusivity_hi_w_s05_m2k": 43.5,
             "nearest": "wood"}
    est = master_state(decode(encode(batch)))["estimate"]
    assert (est["label"], est["effusivity_w_s05_m2k"], est["effusivity_lo_w_s05_m2k"],
            est["effusivity_hi_w_s05_m2k"], est["nearest"]) == ("new material", 42.5, 41.5,
                                                                43.5, "wood")
    js = (Path(__file__).resolve().parents[2] / "src" / "telethermal" / "view" / "static" /
          "view.js").read_text()
    assert "e.effusivity_w_s05_m2k" in js and "nearest: ${e.nearest}" in js


def test_playback_reads_a_recorded_estimates_effusivity():
    # recorder._estimate appends [effusivity, lo, hi, nearest] when the
    # identifier gave them; older recordings hold six items.
    from telethermal.view.playback import _effusivity
    e = [1.0, [1.0, 0.0], "new material", 0.9999, True, "new material", 42.5, 41.5, 43.5,
         "wood"]
    assert _effusivity(e) == {"effusivity_w_s05_m2k": 42.5, "effusivity_lo_w_s05_m2k": 41.5,
                              "effusivity_hi_w_s05_m2k": 43.5, "nearest": "wood"}
    assert _effusivity(e[:6]) == {}
