"""A legitimate touch by a document master, and the checks every hostile
case ends with."""

from __future__ import annotations

from conftest import GUARD_S
from doc_peer import DocMaster


def final_estimate(master: DocMaster, contact_id: int, timeout_s: float = GUARD_S) -> dict:
    """The contact's final material_estimate (section 6a: decisions only,
    then the final one): decided with any reason but "confident group", or
    a group that repeats the previous decision's label (a pair that stood
    until the identifier's last window)."""
    def final():
        decisions = master.of("material_estimate", contact_id=contact_id)
        return [e for i, e in enumerate(decisions) if e["decided"] and (
            e["reason"] != "confident group" or
            (i > 0 and decisions[i - 1]["label"] == e["label"]))]

    assert master.pump(timeout_s, until=final), \
        f"contact {contact_id}: no final decision in {timeout_s} s; slave said " \
        f"{[m['kind'] for _, m in master.received[-8:]]}"
    return final()[-1]


def touch(master: DocMaster, contact_id: int, timeout_s: float = GUARD_S) -> dict:
    """Touch, wait for the slave's decision (and trajectory), lift, wait for
    the slave's lift. Returns the decided estimate."""
    master.touch(contact_id, True)
    estimate = final_estimate(master, contact_id, timeout_s)
    if estimate["label"] != "unknown" and estimate["reason"] != "confident group":
        assert master.pump(GUARD_S, until=lambda: master.of("flux_trajectory",
                                                        contact_id=contact_id)), \
            f"contact {contact_id}: decided {estimate['label']} but no flux_trajectory"
    master.touch(contact_id, False)
    assert master.pump(GUARD_S, until=lambda: master.of("contact_event", contact_id=contact_id,
                                                    touching=False)), \
        f"contact {contact_id}: the slave never lifted"
    return estimate


def place(slave, material: str, seed: int = 0, **args) -> float:
    """Put ``material`` under the pad (the admin socket; ``object_id=``
    names the object); its IR reading."""
    reply = slave.admin("place", material=material, seed=seed, **args)
    assert reply["ok"], reply
    return reply["object_ir_c"]


def announcement(master: DocMaster, object_c: float, object_id: str,
                 timeout_s: float = 2.0) -> dict:
    """The slave's announcement (contact_id 0) of the object just placed
    (newer than any the master has read: call it right after placing)."""
    seen = max((x["seq"] for x in master.of("contact_event", contact_id=0)), default=0)

    def found():
        return [x for x in master.of("contact_event", contact_id=0)
                if abs((x.get("object_temp_c") or 1e9) - object_c) < 1e-9 and
                x.get("object_id") == object_id and x["seq"] > seen]

    assert master.pump(timeout_s, until=found), f"object {object_id} was never announced"
    return found()[-1]


def assert_pad_safe(slave) -> None:
    status = slave.admin("status")
    assert status["ok"] and not status["pad_down"], status
