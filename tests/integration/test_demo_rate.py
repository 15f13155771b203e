"""``telethermal demo --rate-hz``: the master's display loop at another rate
than the default, in the networked touches and in the in-process touch
beside each (under ``--devices qemu`` a lower rate keeps the emulated
boards' UARTs on time: firmware/README.md)."""

import json

import pytest

from telethermal.cli import build_parser, main
from telethermal.control.loop import DEFAULT_RATE_HZ
from telethermal.services.config import load_config
from telethermal.sim.touch import AFTER_RELEASE_S
from telethermal.teleop.session import PRE_CONTACT_S

pytestmark = pytest.mark.slow      # databases, models and two processes (about a minute)

RATE_HZ = 100.0
CONTACT_S = 0.5


def test_the_demo_runs_its_display_at_the_rate_asked_for(tmp_path, capsys):
    assert build_parser().parse_args(["demo"]).rate_hz == DEFAULT_RATE_HZ
    out = tmp_path / "demo"
    assert main(["demo", "--materials", "wood", "--contact-s", str(CONTACT_S),
                 "--rate-hz", f"{RATE_HZ:g}", "--out", str(out), "--seed", "3"]) == 0
    printed = capsys.readouterr().out
    assert f"the display at {RATE_HZ:g} Hz" in printed
    assert load_config(out / "master.toml", "master").rate_hz == RATE_HZ
    report = json.loads((out / "demo.json").read_text())
    assert report["rate_hz"] == RATE_HZ
    # Each networked touch ran its periods at that rate: as many as its
    # simulated display pad has at it (a 500 Hz touch has five times more).
    periods = round((PRE_CONTACT_S + CONTACT_S + AFTER_RELEASE_S) * RATE_HZ)
    touches = report["touches"]
    assert [t["material"] for t in touches] == ["wood", "wood"]
    assert [t["loop_steps"] for t in touches] == [periods, periods]
    # And the in-process touch beside each ran at it, and decided alike.
    assert [t["in_process_rate_hz"] for t in touches] == [RATE_HZ, RATE_HZ]
    assert all(t["in_process_same_decision"] for t in touches), touches
