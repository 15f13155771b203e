"""One touch loop over a pluggable link (issue 45, deliverable 1): the
in-process run and the simulated network drive the same two sides
(sim/sides.py) in the same loop (sim/loop.py); only the link differs. On a
perfect simulated network (no delay, no loss: the services' lossless stream
still numbers, keeps and acknowledges every message) a touch must be the
in-process touch exactly: the same messages reach the master, byte for byte
(msgpack, as on the wire), at the same instants, and the touch's summary is
equal field for field (identified, decision time, memory counters, errors)."""

import math

import msgpack
import numpy as np
import pytest

from telethermal.physics.scene import load_scene, with_finger
from telethermal.sim import sides
from telethermal.sim.inprocess import run_session
from telethermal.sim.channel import Direction
from telethermal.sim.network import NetworkSpec
from telethermal.teleop.display_config import DisplayConfig

SCENE = with_finger(load_scene("fingertip-7"))


def _touch(monkeypatch, models, link, material, seed, **kw):
    """One in-process touch over ``link`` (None: the in-process wire): its
    summary, trace and what reached the master (time, kind, msgpack bytes)."""
    heard = []
    on_message = sides.SimMasterService.on_message

    def tap(self, m, now):
        heard.append((now, m.kind, msgpack.packb(m.fields(), use_bin_type=True)))
        on_message(self, m, now)

    monkeypatch.setattr(sides.SimMasterService, "on_message", tap)
    identifier, generator = models
    result = run_session(SCENE, material, identifier, generator, DisplayConfig(), seed=seed,
                         network=link, **kw)
    monkeypatch.setattr(sides.SimMasterService, "on_message", on_message)
    return result.summary, result.trace, heard


def _same(a, b) -> bool:
    """Equal, NaN equal to NaN (a field with nothing to measure)."""
    if isinstance(a, dict) and isinstance(b, dict):
        return a.keys() == b.keys() and all(_same(a[k], b[k]) for k in a)
    if isinstance(a, (list, tuple)) and isinstance(b, (list, tuple)):
        return len(a) == len(b) and all(_same(x, y) for x, y in zip(a, b))
    if isinstance(a, float) and isinstance(b, float) and math.isnan(a) and math.isnan(b):
        return True
    return a == b


@pytest.fixture(scope="module")
def models(trained_models):
    return trained_models.pair(SCENE, 0)


@pytest.mark.parametrize("material, seed, kw", [
    ("aluminium", 1, {"contact_s": 1.5}),
    ("wood", 2, {"contact_s": 1.5, "expected_material": "wood"}),    # a repeated touch
    ("wood", 3, {"contact_s": 1.5, "expected_material": "steel"}),   # the memory overruled
    ("plexiglass", 4, {"contact_s": 0.05}),      # over before the identifier decides
])
def test_a_perfect_simulated_network_is_the_in_process_wire(monkeypatch, models, material,
                                                             seed, kw):
    wire, wire_trace, wire_heard = _touch(monkeypatch, models, None, material, seed, **kw)
    net, net_trace, net_heard = _touch(monkeypatch, models, NetworkSpec(), material, seed, **kw)
    assert wire_heard == net_heard
    for summary in (wire, net):     # the computer's garbage collections: not the touch's
        summary["loop"] = {k: v for k, v in summary["loop"].items() if not k.startswith("gc_")}
    assert _same(wire, net), {k: (wire[k], net.get(k)) for k in wire
                              if not _same(wire[k], net.get(k))}
    for key, values in wire_trace.items():
        np.testing.assert_array_equal(values, net_trace[key], err_msg=key)
    kinds = [kind for _, kind, _ in wire_heard]
    counts = wire["memory_counts"]
    if kw["contact_s"] < 0.1:
        # Lifted before any decision: no trajectory, the slave's last
        # estimate and its lift after the master's release (stale there).
        assert "flux_trajectory" not in kinds and wire["decision_time_s"] is None
        assert kinds[-1] == "contact_event"
    else:
        assert "flux_trajectory" in kinds and wire["identified"] == material
    # memory_overruled only where a decision disagreed with the memory, on
    # both sides alike.
    overruled = int(kw.get("expected_material", material) != material)
    assert counts["master"]["memory_overruled"] == counts["slave"]["memory_overruled"] \
        == overruled


def test_a_slave_the_lift_has_not_reached_lifts_itself_and_both_sides_count_alike(
        monkeypatch, models):
    # 0.3 s each way: the master's lift is still on the network when the
    # session ends; the slave lifts its pad itself and judges the touch
    # against the memory (a remembered steel; the wood decided overrules it).
    delayed = NetworkSpec.symmetric(Direction(delay_s=0.3))
    summary, _, heard = _touch(monkeypatch, models, delayed, "wood", 3, contact_s=1.5,
                               expected_material="steel")
    assert "flux_trajectory" in [kind for _, kind, _ in heard]
    counts = summary["memory_counts"]
    assert counts["master"]["memory_overruled"] == counts["slave"]["memory_overruled"] == 1
