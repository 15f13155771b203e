"""The slave service's admin requests (``telethermal admin`` against the
slave: PROTOCOL.md's admin section): place an object, calibrate the object
thermometer, forget an object, the last touch's report."""

from __future__ import annotations

import logging

from telethermal.devices.kinds import DeviceKind
from telethermal.ident.anytime import Reason, unknown_reason
from telethermal.ident.openset import EFFUSIVITY_KEYS, effusivity_of, touch_text
from telethermal.services.requests import SLAVE as SLAVE_REQUESTS
from telethermal.services.slave_devices import device_report
from telethermal.teleop.decision import pad_decision
from telethermal.teleop.memory import judged_counts

log = logging.getLogger("telethermal.slave")


def handle_admin(service, request: dict) -> None:
    """One admin request to the slave ``service`` (a SlaveService), answered."""
    def place(r):
        object_id = r.get("object_id")
        if object_id is not None and (not isinstance(object_id, str) or not object_id or
                                      len(object_id.encode()) > 256):
            raise ValueError(f"object_id must be a non-empty string of at most 256 bytes, "
                             f"got {object_id!r}")
        material = str(r["material"])
        seed = int(r["seed"]) if "seed" in r else None
        simulated = service.devices is None or service.devices.kind != DeviceKind.HARDWARE
        if simulated and material not in service.scene.materials:
            raise ValueError(f"scene {service.scene.name} has no object of {material!r}; it "
                             f"has {', '.join(service.scene.materials)}")
        if service.touch_t0 is not None:
            service.lift_for_place()
        seed = service.next_seed() if seed is None else seed
        if service.devices is None:
            # Built off the loop (its heartbeats go on), answered once placed.
            service.place(material, seed, object_id, background=True, reply=True)
            return None
        service.place(material, seed, object_id)
        return place_reply(service)

    def calibrate(r):
        if service.touch_t0 is not None:
            raise ValueError("cannot calibrate during a contact: lift first")
        return service.calibrate_thermometer(float(r.get("drift_k_per_reading", 0.0)))

    def forget(r):
        service.memory.forget(r.get("object_id"))
        log.info("object memory: forgot %s", r.get("object_id") or "every object")
        if service.endpoint.peer_version is not None and service.touch_t0 is None:
            service.announce_object()          # the master forgets it too
        return {"memory": service.memory.to_dict()}

    service.admin.handle(request, service, {
        "place": place, "report": lambda r: dict(service.last_touch),
        "calibrate_thermometer": calibrate, "forget": forget}, SLAVE_REQUESTS)


def place_reply(service) -> dict:
    """The answer to a ``place``: the object placed (object_true_c: the
    simulator's truth, for comparing with direct contact)."""
    pad = service.pad
    return {"object_ir_c": pad.object_ir_c, "object_true_c": pad.object_true_c,
            "object_id": service.object_id, **service.session.object_fields()}


def answer_place(service, error: BaseException | None) -> None:
    """The admin ``place`` waiting for its touch, answered exactly once:
    the object placed, or why it was not."""
    try:
        answer = {"ok": True, **place_reply(service)} if error is None else \
            {"ok": False, "error": f"place: {str(error)[:400]}"}
    except Exception as exc:            # noqa: BLE001 - answered all the same
        answer = {"ok": False, "error": f"place: {str(exc)[:400]}"}
    service.admin.reply(**answer)


def touch_report(service) -> dict:
    """The touch just lifted, as ``admin report`` gives it."""
    pad = service.pad
    decision = pad_decision(pad)
    est = decision.estimate
    return {"material": service.material, "object_true_c": pad.object_true_c,
            "object_ir_c": pad.object_ir_c, "onset_s": pad.onset_s,
            # identified, decision_time_s, identified_at_s: teleop/decision.py
            **decision.fields(),
            "thermometer_calibration_residual_k":
                service.sensors.calibration.to_dict()["residual_k"],
            "reason": est.reason if est is not None else Reason.NO_ESTIMATE,
            # what the memory's counters counted of this touch (PROTOCOL.md 6b)
            "memory_judged": judged_counts(service.session.judgement),
            "unknown_reason": unknown_reason(est),
            # a new material's estimate and nearest class (the last window's
            # estimate otherwise; None: the identifier gives none)
            **dict.fromkeys(EFFUSIVITY_KEYS), **(effusivity_of(est) if est else {}),
            "decision_text": touch_text(est),
            **({"devices": device_report(service.devices, service.counters_at_place)}
               if service.devices is not None else {})}


def slave_status(service) -> dict:
    """The slave's ``status`` (services/slave/README.md lists its fields)."""
    e = service.endpoint
    return {"role": "slave", "state": service.state, "peer_alive": e.peer_alive,
            "material": service.material, "rtt_s": e.offset.rtt_s,
            "object_id": service.object_id, "memory": service.memory.to_dict(),
            "object_true_c": service.pad.object_true_c, "object_ir_c": service.pad.object_ir_c,
            "last_rejected_key": e.last_rejected_key,
            "masters_lost": service.masters_lost,
            "thermometer_calibration": {**service.sensors.calibration.to_dict(),
                                        "error": service.calibration_error},
            "pad_down": service.touch_t0 is not None,
            "next_touch_preparing": service.next_touch_preparing,
            "contact_id": service.contact_id if service.touch_t0 is not None else None,
            "last_sample_t_s": last_sample_t_s(service),
            "peer_session": e.peer_session,
            "offset_s": e.offset.offset_s, "counters": e.all_counters(),
            "admin": dict(service.admin.counters), "time_scale": service.clock.scale,
            "devices": {"kind": service.config.devices,
                        **({"counters": service.devices.all_counters()}
                           if service.devices is not None else {})}}


def last_sample_t_s(service) -> float | None:
    """The touch's last sample read (its ``t_s``), while the pad is down."""
    pad = service.pad
    down = service.touch_t0 is not None and pad is not None and pad.samples_read > 0
    return float(pad.channels["t_s"][pad.samples_read - 1]) \
        if down and "t_s" in pad.channels else None
