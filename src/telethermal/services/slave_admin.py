"""The slave service's admin requests (``telethermal admin`` against the
slave: PROTOCOL.md's admin section): place an object, calibrate the object
thermometer, forget an object, the last touch's report."""

from __future__ import annotations

import logging
import time

from telethermal.services.requests import SLAVE as SLAVE_REQUESTS

log = logging.getLogger("telethermal.slave")


def handle_admin(service, request: dict) -> None:
    """One admin request to the slave ``service`` (a SlaveService), answered."""
    def place(r):
        object_id = r.get("object_id")
        if object_id is not None and (not isinstance(object_id, str) or not object_id or
                                      len(object_id.encode()) > 256):
            raise ValueError(f"object_id must be a non-empty string of at most 256 bytes, "
                             f"got {object_id!r}")
        if service.touch_t0 is not None:
            # The pad is moved to another object: the contact going on
            # ends first (its lift may still be on the way from the master).
            cause = service._place_lift_cause()
            log.warning("place during contact_id=%d: the pad is lifted first (%s)",
                        service.contact_id, cause)
            service.counters[cause] += 1
            if cause == "masters_lost":
                service.masters_lost += 1
            service._lift(time.monotonic())
        service._next_prepared(wait=True)     # the seed after the last lift's
        service.place(str(r["material"]), int(r.get("seed", service._seed + 1)), object_id)
        # object_true_c: the simulator's truth, for comparing with direct contact
        pad = service.pad
        return {"object_ir_c": pad.object_ir_c, "object_true_c": pad.object_true_c,
                "object_id": service.object_id, **service.session.object_fields()}

    def calibrate(r):
        if service.touch_t0 is not None:
            raise ValueError("cannot calibrate during a contact: lift first")
        return service.calibrate_thermometer(float(r.get("drift_k_per_reading", 0.0)))

    def forget(r):
        service.memory.forget(r.get("object_id"))
        log.info("object memory: forgot %s", r.get("object_id") or "every object")
        if service.endpoint.peer_version is not None and service.touch_t0 is None:
            service._announce_object()          # the master forgets it too
        return {"memory": service.memory.to_dict()}

    service.admin.handle(request, service, {
        "place": place, "report": lambda r: dict(service.last_touch),
        "calibrate_thermometer": calibrate, "forget": forget}, SLAVE_REQUESTS)
