"""The simulator, as the services reach it: by name, imported when a
simulated touch is made, as python-can's ``BACKENDS`` reach its virtual bus
(and :data:`~telethermal.devices.display.DISPLAYS` its QEMU display). The
services run on hardware without the :mod:`telethermal.sim` package; the
kinds ``sim``, ``emulated`` and ``qemu`` need it for the world behind their
devices (the operator, the pads' physics, the direct-contact reference).
"""

from __future__ import annotations

import importlib

from telethermal.devices.board import DeviceError

#: What a service takes from the simulator, by name: (module, attribute).
SIMULATED = {
    #: The master's side of a touch: ``MasterWorld(scene, seed)``.
    "master_touch": ("telethermal.sim.touch", "MasterWorld"),
    #: The same finger touching the object directly:
    #: ``compare_with_direct(scene, material, object_c, operator, trace, contact_s, from_s)``.
    "direct_contact": ("telethermal.sim.direct", "compare_with_direct"),
}


def simulated(name: str):
    """The simulator's ``name`` (:data:`SIMULATED`); a
    :class:`~telethermal.devices.board.DeviceError` naming the module when this
    install has no simulator."""
    try:
        module, attribute = SIMULATED[name]
    except KeyError:
        raise ValueError(f"the simulator has no {name!r} (it has: "
                         f"{', '.join(sorted(SIMULATED))})") from None
    try:
        return getattr(importlib.import_module(module), attribute)
    except ImportError as e:
        raise DeviceError(f"a simulated touch needs the simulator ({module}), which this "
                          f"install cannot import ({e}); on hardware set devices = "
                          "'hardware'") from e
