"""The display's idle policy as the product applies it: shipped per scene,
cached for others, never used stale; every driver idles the same way."""

import json
import math

import numpy as np
import pytest

from telethermal.control import preconditioning as pc

from telethermal.control import display_floor
from telethermal.errors import ControlError, UnknownMaterialError
from telethermal.physics.scene import list_scenes, load_scene, with_finger
from telethermal.teleop.link import SlaveLink
from telethermal.teleop.display_config import DisplayConfig
from telethermal.teleop.display_setup import display_idle


@pytest.fixture(autouse=True)
def _fresh(monkeypatch, tmp_path):
    """Each test with its own cache folder and nothing remembered."""
    monkeypatch.setenv("TELETHERMAL_CACHE", str(tmp_path / "cache"))
    monkeypatch.setattr(pc, "_POLICIES", {})


@pytest.fixture
def scene():
    return with_finger(load_scene("fingertip-7"))


def test_shipped_policies_are_current():
    """A policy the package ships was computed for the scene as it is now
    (else it would be recomputed at every first use: regenerate it with
    ``telethermal scenes --write-idle-policy NAME``)."""
    shipped = [n for n in list_scenes() if pc.shipped_policy_path(n).is_file()]
    assert "fingertip-7" in shipped
    for name in shipped:
        data = json.loads(pc.shipped_policy_path(name).read_text())
        assert data["key"] == pc.policy_key(with_finger(load_scene(name))), name


def test_the_key_follows_the_physics_not_the_descriptions(scene, monkeypatch):
    """A part's ``source`` text (a datasheet name, a pointer into the docs)
    leaves the key alone; one figure of the heat sink changes it."""
    import copy

    from telethermal.physics import thermoelectric as te

    base = pc.policy_key(scene)
    table = copy.deepcopy(te._table())

    def patched(edit):
        t = copy.deepcopy(table)
        edit(t)
        monkeypatch.setattr(te, "_table", lambda: t)
        return pc.policy_key(scene)

    sink = te.DEFAULT_HEAT_SINK
    module = te.DEFAULT_MODULE
    assert patched(lambda t: t["heat_sinks"][sink].update(source="moved to another page")) == base
    assert patched(lambda t: t["modules"][module].update(source="another datasheet")) == base
    assert patched(lambda t: t["heat_sinks"][sink].update(
        to_air_k_w=t["heat_sinks"][sink]["to_air_k_w"] * 1.1)) != base


def test_a_scene_naming_another_module_gets_its_hardware_and_its_own_key(scene, monkeypatch):
    """A catalogue with a second module (the default's Qmax and Imax
    doubled): a scene whose [pad] names it gets that module in the display
    floor's hardware (the idle policy's search) and another policy key;
    the scene naming the default keeps its own."""
    import copy
    import dataclasses

    from telethermal.control import display_floor
    from telethermal.physics import thermoelectric as te

    base = pc.policy_key(scene)
    table = copy.deepcopy(te._table())
    other = dict(table["modules"][te.DEFAULT_MODULE])
    other.update(qmax_w=2 * other["qmax_w"], imax_a=2 * other["imax_a"])
    table["modules"]["TWICE-1"] = other
    monkeypatch.setattr(te, "_table", lambda: table)
    named = dataclasses.replace(scene, pad=dataclasses.replace(scene.pad, module="TWICE-1"))
    assert display_floor.hardware(named).params.spec.qmax_w == 2 * display_floor.hardware(
        scene).params.spec.qmax_w
    assert pc.policy_key(named) != base and pc.policy_key(scene) == base


def test_the_shipped_policy_is_used_without_computing(scene, monkeypatch):
    def refuse(_scene):
        raise AssertionError("computed although the package ships the policy")
    monkeypatch.setattr(pc, "compute_policy", refuse)
    policy = pc.scene_policy(scene)
    assert policy["key"] == pc.policy_key(scene)
    # The minimax idle is below the object for fingertip-7 (between the
    # metals' and the insulators' best idles, bench/results/skin-floor.json).
    fractions = pc.policy_fractions(scene)
    assert fractions["aluminium"] < fractions[pc.UNKNOWN_KEY] < fractions["wood"]


def test_a_stale_or_missing_policy_is_computed_once_and_cached(scene, monkeypatch, tmp_path):
    changed = load_scene("fingertip-7").__class__(**{**vars(scene), "room_temp_c": 22.0})
    assert pc.policy_key(changed) != pc.policy_key(scene)
    # A pad face of its own is another display: another policy.
    import dataclasses
    sized = dataclasses.replace(scene, pad=dataclasses.replace(scene.pad, size_mm=(15.0, 15.0)))
    assert pc.policy_key(sized) != pc.policy_key(scene)
    calls = []

    def fake(s):
        calls.append(s.room_temp_c)
        return {"scene": s.name, "key": pc.policy_key(s), "version": pc.POLICY_VERSION,
                "minimax": {"fraction_of_finger_minus_object": -0.25},
                "expected": {"fraction_of_finger_minus_object": -0.2},
                "preconditioned": {m: {"fraction_of_finger_minus_object": 0.1}
                                   for m in s.materials}, "groups": {}}
    monkeypatch.setattr(pc, "compute_policy", fake)
    assert pc.scene_policy(changed)["minimax"]["fraction_of_finger_minus_object"] == -0.25
    cached = list((tmp_path / "cache").glob("idle-policy-*.json"))
    assert len(cached) == 1 and not list((tmp_path / "cache").glob(".*tmp"))
    monkeypatch.setattr(pc, "_POLICIES", {})
    pc.scene_policy(changed)                    # from the cache file, not computed again
    assert calls == [22.0]


def test_a_file_that_is_not_a_policy_is_named(scene, tmp_path, monkeypatch):
    folder = tmp_path / "cache"
    folder.mkdir()
    changed = scene.__class__(**{**vars(scene), "room_temp_c": 21.0})
    bad = folder / f"idle-policy-{pc.policy_key(changed)}.json"
    bad.write_text("{not json")
    with pytest.raises(ControlError, match="not an idle policy"):
        pc.scene_policy(changed)
    assert bad.read_text() == "{not json"       # nothing overwritten


def test_idle_rule_and_its_errors(scene):
    fractions = {pc.UNKNOWN_KEY: -0.5, "aluminium": -2.0}
    assert pc.idle_from_fractions(fractions, None, 24.0, 33.0) == pytest.approx(19.5)
    assert pc.idle_from_fractions(fractions, "aluminium", 24.0, 33.0) == 15.0   # band edge
    with pytest.raises(UnknownMaterialError, match="steel"):
        pc.idle_from_fractions(fractions, "steel", 24.0, 33.0)
    with pytest.raises(ControlError, match="finite"):
        pc.idle_from_fractions(fractions, None, math.nan, 33.0)


def test_display_idle_by_config(scene):
    """"policy": shifted by the policy (the same for every driver);
    "object": at the object; an unknown object temperature: neutral."""
    idle, shift = display_idle(scene, DisplayConfig(), 33.0, 24.0)
    assert shift is not None
    assert idle == pytest.approx(pc.idle_for(scene, None, 24.0, 33.0))
    assert idle < 24.0
    known, _ = display_idle(scene, DisplayConfig(), 33.0, 24.0, "aluminium")
    assert known == pytest.approx(pc.idle_for(scene, "aluminium", 24.0, 33.0))
    assert display_idle(scene, DisplayConfig(idle="object"), 33.0, 24.0) == (24.0, None)
    neutral, _ = display_idle(scene, DisplayConfig(), 33.0, None)
    assert neutral == DisplayConfig().limits.neutral_c
    with pytest.raises(ControlError, match="idle"):
        DisplayConfig(idle="warm")


def test_the_link_expects_the_announced_material_or_pair():
    link = SlaveLink(classes=("aluminium", "wood", "rubber"))
    assert link.expected_material is None
    link.remembered = ("wood", 0.9)
    assert link.news(0.0, True).expected_material == "wood"
    link.remembered = ("rubber|wood", 0.9)            # a pair: its own idle
    assert link.expected_material == "rubber|wood"
    link.remembered = ("glass", 0.9)                  # not a class of this slave
    assert link.expected_material is None
    link.remembered = ("glass|wood", 0.9)
    assert link.expected_material is None


def test_a_remembered_pair_idles_at_the_pairs_minimax(scene):
    """The pair's idle minimises the worse of its two materials' floors on
    the shipped table: no idle on the table's fine grid does better for the
    pair, it lies between the two materials' own best idles, and for
    plexiglass|rubber (the pair bench faults' memory holds) both floors are
    far below what the idle for an unknown object gives them."""
    policy = pc.scene_policy(scene)
    table, pair = policy["table"], ("plexiglass", "rubber")
    row = policy["groups"]["plexiglass|rubber"]
    idle_c, worst_k = pc.group_minimax_idle(table, pair)
    assert (idle_c, worst_k) == (row["idle_c"], row["worst_floor_k"])
    grid = table["idle_c"]
    worst = [max(table["floor_k"][m][i] for m in pair) for i in range(len(grid))]
    assert worst_k <= min(worst) + 1e-12
    best = sorted(policy["preconditioned"][m]["idle_c"] for m in pair)
    assert best[0] - 1.0 <= idle_c <= best[1] + 1.0          # the table's step
    unknown = policy["minimax"]["idle_c"]
    floor_unknown = max(float(np.interp(unknown, grid, table["floor_k"][m])) for m in pair)
    assert worst_k < 0.25 * floor_unknown
    fractions = pc.policy_fractions(scene)
    assert fractions["plexiglass|rubber"] == row["fraction_of_finger_minus_object"]
    # The policy's pair keys are the identifier's group labels.
    from telethermal.ident.label import GROUP_SEPARATOR, Label
    assert pc.PAIR_SEPARATOR == GROUP_SEPARATOR
    assert all(Label(key).is_group and key == Label.of(Label(key).members)
               for key in policy["groups"])
    idle, _ = display_idle(scene, DisplayConfig(), 33.0, 24.0, "plexiglass|rubber")
    assert idle == pytest.approx(24.0 + row["fraction_of_finger_minus_object"] * 9.0, abs=1e-9)


def test_the_pairs_idle_read_off_the_table_is_the_floors_there(scene):
    # The table is interpolated between 1 K points; at the idle chosen for
    # plexiglass|rubber the two floors, solved there (the search's own
    # solver), are within 0.02 K of the table's worst (a fifth of the
    # unknown object's idle's 0.36 K), and the worse of them is the
    # table's to within that.
    policy = pc.scene_policy(scene)
    row = policy["groups"]["plexiglass|rubber"]
    search = pc.FloorSearch(scene, display_floor.hardware(scene),
                            display_floor.nominal_touch(scene))
    solved = [search.floor_k(m, row["idle_c"]) for m in ("plexiglass", "rubber")]
    assert max(solved) == pytest.approx(row["worst_floor_k"], abs=0.02)
    assert pc.idle_for(scene, "plexiglass|rubber", 24.0, 33.0) == pytest.approx(
        24.0 + row["fraction_of_finger_minus_object"] * 9.0)
    with pytest.raises(UnknownMaterialError, match="glass"):
        pc.idle_for(scene, "glass|wood", 24.0, 33.0)


def test_a_label_without_an_idle_idles_as_an_unknown_object(caplog):
    shift = pc.precondition_from({pc.UNKNOWN_KEY: -0.5, "wood": 0.2}, 33.0)
    assert shift("wood", 24.0) == pytest.approx(1.8)
    with caplog.at_level("INFO", logger="telethermal.preconditioning"):
        for _ in range(3):                          # every display period: said once
            assert shift("a|b|c", 24.0) == shift(None, 24.0) == pytest.approx(-4.5)
    assert sum("no idle for 'a|b|c'" in r.getMessage() for r in caplog.records) == 1
