"""The typed decision: :class:`Label` (one material, a group, unknown) and
:class:`Reason`, both the strings the wire and recordings have always held."""

from __future__ import annotations

import json
from pathlib import Path

import msgpack
import pytest
from hypothesis import given
from hypothesis import strategies as st

from telethermal.ident.anytime import (GROUP_SEPARATOR, UNKNOWN, Decision, Estimate, group_label,
                                       members)
from telethermal.ident.label import Label, Reason
from telethermal.record.recording import read_recording

OLD_RECORDING = Path(__file__).parents[1] / "data" / "wood-59b2bb7.mcap"

names = st.text(min_size=1, max_size=20).filter(
    lambda s: GROUP_SEPARATOR not in s and s != "unknown")


@given(st.lists(names, min_size=1, max_size=4, unique=True))
def test_format_parse_round_trip(materials):
    label = Label.of(materials)
    text = str(label)
    assert type(text) is str and text == GROUP_SEPARATOR.join(sorted(materials))
    back = Label.parse(text)
    assert back == label and back.members == tuple(sorted(materials))
    assert back.is_group == (len(materials) > 1)
    assert back.is_material == (len(materials) == 1)
    assert not back.is_unknown
    assert all(back.holds(m) for m in materials)
    assert back.within(materials) and not back.within(materials[1:])


@given(names, names)
def test_a_pair_is_sorted_and_knows_its_members(a, b):
    if a == b:
        return
    pair = Label.of([b, a])
    assert pair == f"{min(a, b)}|{max(a, b)}"
    assert pair.is_group and not pair.is_material and not pair.is_unknown
    assert pair.members == (min(a, b), max(a, b))
    assert group_label([b, a]) == pair and type(group_label([b, a])) is str


def test_a_pair_from_a_recording():
    pair = Label.parse("rubber|wood")
    assert pair.members == ("rubber", "wood") and pair.is_group
    assert pair.holds("wood") and not pair.holds("woo") and not pair.holds("rubber|wood")
    assert members("rubber|wood") == ("rubber", "wood")


def test_one_material():
    steel = Label("steel")
    assert steel.members == ("steel",) and steel.is_material
    assert not steel.is_group and not steel.is_unknown
    assert steel.within(["steel", "wood"]) and not steel.within(["wood"])


def test_unknown_stands_for_no_material():
    assert UNKNOWN == "unknown" and Label.parse("unknown") is not None
    for label in (UNKNOWN, Label.parse("unknown"), Label()):
        assert label.is_unknown and not label.is_group and not label.is_material
        assert label.members == () and not label.within(["unknown"])
        assert not label.holds("unknown")


def test_of_refuses_what_is_no_material():
    for bad in ([], ["a|b"], [""], ["unknown"], ["a", "unknown"]):
        with pytest.raises(ValueError):
            Label.of(bad)
    with pytest.raises(TypeError):
        Label(3)


def test_a_label_is_its_string_on_the_wire_and_in_files():
    pair = Label.of(["wood", "rubber"])
    assert pair == "rubber|wood" and hash(pair) == hash("rubber|wood")
    assert {"rubber|wood": 1}[pair] == 1 and pair in {"rubber|wood"}
    assert msgpack.packb([pair, Reason.CONFIDENT_GROUP], use_bin_type=True) == \
        msgpack.packb(["rubber|wood", "confident group"], use_bin_type=True)
    assert json.dumps({pair: Reason.CONFIDENT}) == '{"rubber|wood": "confident"}'
    assert repr(pair) == repr("rubber|wood") and f"{pair}" == "rubber|wood"


def test_estimates_and_decisions_hold_labels():
    e = Estimate(0.1, (0.5, 0.5), "rubber|wood", 0.9, True, "confident group")
    assert type(e.label) is Label and e.label.is_group and not e.final
    d = Decision("unknown", 0.0, None, "gap too small")
    assert type(d.label) is Label and d.label.is_unknown
    assert Estimate(0.0, (1.0,), "x", 1.0, False).reason == Reason.UNDECIDED == ""


def test_reason_values_are_the_recorded_strings():
    assert {r.value for r in Reason} == {
        "", "confident", "confident group", "outside classes", "new material", "gap too small",
        "not confident", "force outside trained range", "object memory",
        "sensor board lost", "no object temperature", "pad model does not fit: recalibrate",
        "pad model does not fit: named by the fallback",
        "no estimate", "no decision", "slave restarted"}
    assert Reason("confident group") is Reason.CONFIDENT_GROUP
    assert not Reason.UNDECIDED and str(Reason.OBJECT_MEMORY) == "object memory"


def test_an_old_recording_reads_as_labels_and_reasons():
    rec = read_recording(OLD_RECORDING)
    reasons, labels = set(), set()
    for m in rec.messages("/slave/estimates"):
        e = m["estimate"]
        reasons.add(e[5])
        labels.add(Label.parse(e[2]))
    assert reasons == {"", "confident", "confident group"}
    assert {Reason(r) for r in reasons} == {Reason.UNDECIDED, Reason.CONFIDENT,
                                           Reason.CONFIDENT_GROUP}
    assert labels == {"rubber", "rubber|wood", "wood"}
    assert [lab.members for lab in sorted(labels)] == [("rubber",), ("rubber", "wood"),
                                                        ("wood",)]
