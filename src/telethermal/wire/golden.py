"""Golden vectors: one example message per kind, encoded, beside its JSON.

``python -m telethermal.wire.golden DIR`` (re)writes ``DIR/<name>.msgpack``
and ``DIR/<name>.json`` (the name is the kind, or ``<kind>.<variant>`` for a
further example of a kind); the committed files in ``proto/golden/`` are what the
codec is tested against, both ways, so a change of encoding shows up as a
failing test rather than as a silent incompatibility.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

from telethermal.wire.codec import encode

_ENV = {"v": 1, "seq": 7, "sent_s": 1234.5625}
EXAMPLES = {
    "hello": {"role": "master", "versions": [1], "software": "telethermal 0.1.0",
              "session_id": "4f2a9c1e", "resume_from": 1},
    "heartbeat": {"ack": 6, "echo_sent_s": 1234.5, "echo_held_s": 0.00025, "last_seq": 9},
    "resend": {"from_seq": 4},
    "session_config": {"scene": "fingertip-7", "sample_rate_hz": 100.0,
                       "classes": ["plexiglass", "steel"], "identifier": "effusivity-lda",
                       "threshold": 0.99,
                       "curves": {"plexiglass": {"t_s": [0.01, 0.1, 1.0],
                                                 "g_w_m2k": [120.5, 410.25, 160.0]},
                                  "steel": {"t_s": [0.01, 0.1, 1.0],
                                            "g_w_m2k": [350.0, 1200.5, 640.0]}}},
    "contact_event": {"contact_id": 3, "touching": True, "t_s": 1234.25, "force_n": 2.125,
                      "finger_temp_c": 33.25},
    # The slave's object announcement (contact_id 0) with what its object
    # memory holds for that object.
    "contact_event.object": {"contact_id": 0, "touching": False, "t_s": 1230.5,
                             "force_n": 0.0, "object_temp_c": 23.75, "object_id": "cup-2",
                             "object_material": "steel", "object_confidence": 0.9921875},
    # The same for an object remembered as a new material, with the memory's
    # estimate of it (section 6b).
    "contact_event.object_new": {"contact_id": 0, "touching": False, "t_s": 1230.5,
                                 "force_n": 0.0, "object_temp_c": 23.75,
                                 "object_id": "glass-1", "object_material": "new material",
                                 "object_confidence": 0.998046875,
                                 "object_effusivity_w_s05_m2k": 1390.0,
                                 "object_effusivity_lo_w_s05_m2k": 1270.0,
                                 "object_effusivity_hi_w_s05_m2k": 1520.0},
    "material_estimate": {"contact_id": 3, "t_since_contact_s": 0.25,
                          "classes": ["plexiglass", "steel"], "posteriors": [0.125, 0.875],
                          "label": "steel", "confidence": 0.875, "decided": False,
                          "reason": "", "object_temp_c": 24.5},
    # A new material (issue 30): decided outside every class, with the
    # effusivity estimate, its 95 % interval and the nearest class.
    "material_estimate.new": {"contact_id": 3, "t_since_contact_s": 1.0,
                              "classes": ["plexiglass", "steel"], "posteriors": [1.0, 0.0],
                              "label": "new material", "confidence": 0.9999847412109375,
                              "decided": True, "reason": "new material", "object_temp_c": 24.5,
                              "effusivity_w_s05_m2k": 1390.0,
                              "effusivity_lo_w_s05_m2k": 1270.0,
                              "effusivity_hi_w_s05_m2k": 1520.0, "nearest": "plexiglass"},
    "flux_trajectory": {"contact_id": 3, "material": "steel", "object_temp_c": 24.5,
                        "t_s": [0.0, 0.5, 1.0], "g_w_m2k": [0.0, 900.0, 640.0],
                        "valid_s": 60.0},
    "flux_setpoint": {"contact_id": 3, "t_since_contact_s": 0.5, "flux_w_m2": -7650.0},
    "posterior_estimate": {"contact_id": 3, "t_since_contact_s": 0.125,
                           "classes": ["plexiglass", "steel"], "posteriors": [0.25, 0.75],
                           "label": "steel", "confidence": 0.75, "decided": False,
                           "reason": "", "object_temp_c": 24.5},
    # An undecided estimate of an identifier that estimates the effusivity.
    "posterior_estimate.effusivity": {"contact_id": 3, "t_since_contact_s": 0.125,
                                      "classes": ["plexiglass", "steel"],
                                      "posteriors": [0.25, 0.75], "label": "steel",
                                      "confidence": 0.75, "decided": False, "reason": "",
                                      "object_temp_c": 24.5,
                                      "effusivity_w_s05_m2k": 7250.0,
                                      "effusivity_lo_w_s05_m2k": 5500.0,
                                      "effusivity_hi_w_s05_m2k": 9600.0},
    # A master's batch on its view stream, with the optional fields (a
    # slave's batch is the same without them).
    "measurement_batch": {"contact_id": 3, "t0_s": 1234.0, "rate_hz": 100.0,
                          "flux_w_m2": [-120.5, -3400.0], "temp_c": [34.5, 33.75],
                          "force_n": [9.5, 10.25], "setpoint_w_m2": -3500.0,
                          "skin_temp_c": 33.5, "phase": "render", "safe": False,
                          "events": {"link lost": 0}, "link": {"stream_lost": 2, "resent": 1},
                          "rtt_s": 0.00025, "classes": ["plexiglass", "steel"],
                          "posteriors": [0.125, 0.875], "label": "steel", "decided": True,
                          "estimate_t_s": 0.25},
    "status": {"state": "rendering", "counters": {"resent": 0, "heartbeats_missed": 1},
               "message": "ok"},
    "fault": {"code": "sensor-nan", "message": "heat-flux reading NaN", "safe_state": True},
}


def messages() -> dict[str, dict]:
    """Vector name -> message. A name is its kind, or ``kind.variant`` for a
    further example of a kind (its optional fields, say)."""
    return {name: {"kind": name.split(".")[0], **_ENV, **fields}
            for name, fields in EXAMPLES.items()}


def write(folder: str | Path) -> list[Path]:
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    written = []
    for name, message in messages().items():
        (folder / f"{name}.msgpack").write_bytes(encode(message))
        (folder / f"{name}.json").write_text(json.dumps(message, indent=2) + "\n")
        written.append(folder / f"{name}.msgpack")
    return written


if __name__ == "__main__":
    for path in write(sys.argv[1] if len(sys.argv) > 1 else "proto/golden"):
        print(path)
