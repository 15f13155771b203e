"""The product without its simulator (issue 45): every module of the product's
layers imports with ``telethermal.sim`` absent, as a lab's install could
ship it, and a simulated touch then fails with an error naming what is
missing; with the simulator, every name the services reach it by resolves."""

from __future__ import annotations

import subprocess
import sys

import pytest

from telethermal.devices.simulated import SIMULATED, simulated

PRODUCT = ("physics", "control", "wire", "devices", "data", "ident", "render",
           "record", "teleop", "view", "services")

WITHOUT_SIM = f"""
import importlib, pkgutil, sys
sys.modules["telethermal.sim"] = None          # an install without the simulator
import telethermal
imported = 0
for name in {PRODUCT!r}:
    package = importlib.import_module("telethermal." + name)
    for info in pkgutil.walk_packages(package.__path__, package.__name__ + "."):
        importlib.import_module(info.name)
        imported += 1
print("imported", imported)
from telethermal.devices.simulated import simulated
try:
    simulated("master_touch")
except Exception as e:
    print("refused:", type(e).__name__, e)
"""


def test_the_product_imports_without_the_simulator_and_a_simulated_touch_says_why_not():
    out = subprocess.run([sys.executable, "-c", WITHOUT_SIM], capture_output=True, text=True,
                         timeout=300)
    assert out.returncode == 0, out.stderr
    lines = out.stdout.splitlines()
    assert int(lines[0].split()[1]) > 100          # every module of those layers
    assert lines[1].startswith("refused: DeviceError")
    assert "telethermal.sim.touch" in lines[1] and "devices = 'hardware'" in lines[1]


@pytest.mark.parametrize("name", sorted(SIMULATED))
def test_every_simulated_name_resolves(name):
    assert callable(simulated(name))


def test_an_unknown_simulated_name_is_refused_naming_the_known_ones():
    with pytest.raises(ValueError, match="no 'operator'.*direct_contact, master_touch"):
        simulated("operator")
