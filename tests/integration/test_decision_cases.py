"""Issue 29's soak, the slave's side: the demo's 22 touches (`telethermal
demo --materials` with the 7 materials three times, seed 13) once committed
rubber as plexiglass in the second round, and the object memory then
announced the third touch of the same object as plexiglass. Here the three
rubber touches of that soak (the demo's trial seeds, the slave's
instruments and calibration drawn as its service draws them, the
identifier trained on the seed's database in memory: the demo trains it
from the database written to disk): each is decided rubber,
and the memory the slave builds from them announces rubber before the
third."""

import pytest

from telethermal.physics.scene import load_scene, with_finger
from telethermal.sim.inprocess import service_sensors
from telethermal.teleop.memory import ObjectMemory
from telethermal.teleop.models import train_identifier
from telethermal.teleop.slave import Slave, slave_rng

SCENE = with_finger(load_scene("fingertip-7"))
DEMO_SEED = 13
#: The demo's touch i uses seed DEMO_SEED + 1 + i; rubber is the 6th material.
RUBBER_SEEDS = [DEMO_SEED + 1 + i for i in (5, 12, 19)]


@pytest.mark.slow          # over 10 s here: make test-all and CI run it
def test_the_soak_rubber_touches_are_rubber_and_remembered_so():
    identifier = train_identifier(SCENE, DEMO_SEED)
    # The slave service's instruments and calibration, drawn as the service
    # draws them for its seed (SlaveService._start_sensor_session).
    session = service_sensors(SCENE, DEMO_SEED)
    memory = ObjectMemory(identifier.threshold)
    announced = []
    for seed in RUBBER_SEEDS:
        r = memory.recall("rubber")
        announced.append(None if r is None else r.material)
        pad = Slave(SCENE, "rubber", identifier, slave_rng(seed), session=session)
        pad.advance_to(10.0)
        assert pad.estimate.decided and pad.estimate.label == "rubber", (seed, pad.estimate)
        memory.learn("rubber", pad.estimate, float(seed), classes=pad.classes)
    assert announced == [None, "rubber", "rubber"]


@pytest.mark.slow          # over 10 s here: make test-all and CI run it
def test_the_emulated_seed_5_plexiglass_touch_is_never_committed_as_rubber(tmp_path,
                                                                          trained_models):
    # `telethermal demo --devices emulated --materials wood,aluminium,plexiglass
    # --seed 5` once committed plexiglass as rubber at 0.1 s (effusivity-lda,
    # the default then). The same services, devices, seeds and touches here
    # (the emulated boards stream on the real clock, so the noise each touch
    # gets is not the same draw twice: the property is checked on whatever
    # this run draws). With effusivity-lda as the default it fails here (run
    # once when this test was written). A class commitment is final, so a
    # touch that ends plexiglass never said rubber; an honest pair on the
    # way is allowed.
    from telethermal.demo.run import Services, wait_connected, write_configs
    from telethermal.demo.touches import networked_touch
    from telethermal.ports import free_ports
    from telethermal.teleop.models import DEFAULT_METHOD

    seed = 5
    ident_path, gen_path = trained_models.files(SCENE, seed)
    ports = free_ports(4)
    slave_cfg, master_cfg = write_configs(tmp_path, SCENE.name, ident_path, gen_path, ports,
                                          seed, devices="emulated")
    services = Services(tmp_path, slave_cfg, master_cfg)
    said = {}
    try:
        wait_connected(services, ports[3])
        for i, material in enumerate(("wood", "aluminium", "plexiglass")):
            s = networked_touch(SCENE, material, ports, seed + 1 + i, contact_s=1.5).summary
            said[material] = (s["identified"], s["safety_events"])
    finally:
        codes = services.stop()
    assert codes == {"slave": 0, "master": 0}
    assert trained_models.identifier(SCENE, seed).method == DEFAULT_METHOD
    assert said["plexiglass"][0] == "plexiglass", said
