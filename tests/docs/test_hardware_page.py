"""The hardware page's bill of materials covers every part the simulator
models, each row with its figure, default, alternative, price and source;
the module and heat sink it names are the ones physics/modules.toml holds,
with the same figures; the wiring figure exists and is linked."""

from __future__ import annotations

import re
import tomllib
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
PAGE = ROOT / "docs" / "hardware.md"
MODULES = ROOT / "src" / "telethermal" / "physics" / "modules.toml"

#: Every part a scene's physics or a driver models (physics/sensors.py,
#: physics/thermoelectric.py, devices/), and what a board needs to read them.
PARTS = ["Peltier module", "heat-flux sensor", "pad thermocouple", "thermistors",
         "reference probe", "force sensor", "IR thermometer", "ADC", "microcontroller",
         "H-bridge", "CAN transceiver", "power supply", "heat sink and fan"]


def bom_rows() -> dict[str, list[str]]:
    text = PAGE.read_text()
    table = text[text.index("## Bill of materials"):text.index("## Wiring")]
    rows = [line.strip().strip("|").split("|") for line in table.splitlines()
            if line.startswith("|") and not line.startswith("|---")]
    header, body = rows[0], rows[1:]
    assert [h.strip() for h in header] == ["part", "figure that matters",
                                          "default (what the simulator models)", "alternative",
                                          "price", "source of the figures"]
    return {cells[0].strip(): [c.strip() for c in cells[1:]] for cells in body}


def test_every_modelled_part_has_a_full_row():
    rows = bom_rows()
    missing = [p for p in PARTS if not any(name.startswith(p) for name in rows)]
    assert missing == [], f"parts without a row: {missing}"
    for name, cells in rows.items():
        assert len(cells) == 5 and all(cells), f"{name}: an empty cell"
        assert re.search(r"~\s?\d", cells[3]), f"{name}: no price order ({cells[3]!r})"


def test_the_module_and_sink_are_the_simulators_with_its_figures():
    table = tomllib.loads(MODULES.read_text())
    text = PAGE.read_text()
    for key, module in table["modules"].items():
        assert key.replace("TM-", "TM ") in text, key
        for figure in (f"Imax {module['imax_a']:g} A", f"Vmax {module['vmax_v']:g} V",
                       f"Qmax {module['qmax_w']:g} W", f"dTmax {module['dtmax_k']:g} K",
                       f"{module['hot_side_max_c']:g} C"):
            assert figure in text, figure
    for sink in table["heat_sinks"].values():
        assert f"{sink['to_air_k_w']:.1f} K/W" in text


def test_the_wiring_figure_is_there_and_linked():
    svg = ROOT / "docs" / "hardware-wiring.svg"
    assert svg.read_text().lstrip().startswith("<svg") and "](hardware-wiring.svg)" in PAGE.read_text()
    for part in ("heat-flux sensor", "H-bridge", "CAN transceiver", "Peltier module", "IR thermometer"):
        assert part in svg.read_text(), part
