"""The master makes its display's idle policy ready before it opens its
sockets: a scene with none shipped or cached (a lab's own, or a shipped one
whose table went stale) computes it at start, saying so, instead of in the
first touch, where the master's admin went unanswered for minutes (the
compose test's master looked dead)."""

from __future__ import annotations

import logging

import pytest

from telethermal.control import preconditioning as pc
from telethermal.services import master as master_module
from telethermal.services.config import MasterConfig
from telethermal.ports import free_ports
from telethermal.services.master import MasterService
from telethermal.wire.transport import TransportConfig


def _config(**kw) -> MasterConfig:
    control, stream, admin = free_ports(3)
    return MasterConfig(seed=5, admin_port=admin, transport=TransportConfig(
        security="plain", control_port=control, stream_port=stream), **kw)


@pytest.mark.parametrize("idle, computed", [("policy", True), ("object", False)])
def test_the_policy_is_ready_before_the_master_listens(monkeypatch, caplog, idle, computed):
    order = []
    opened = master_module.open_service_sockets
    monkeypatch.setattr(pc, "policy_known", lambda scene: False)
    monkeypatch.setattr(pc, "scene_policy", lambda scene: order.append("policy") or {})
    monkeypatch.setattr(master_module, "open_service_sockets",
                        lambda *a: order.append("sockets") or opened(*a))
    with caplog.at_level(logging.WARNING, "telethermal.master"):
        service = MasterService(_config(idle=idle))
    service.shutdown()
    assert order == (["policy", "sockets"] if computed else ["sockets"])
    assert ("idle policy for scene fingertip-7: computing (minutes, once)" in caplog.text) \
        == computed
