"""``telethermal bench transport``: the wire's cost, beside raw pyzmq.

- Encode and decode time per message kind (the golden examples).
- Slave -> master one-way latency of a ``material_estimate`` through the whole
  stack (codec, validation, sequence numbers, the lossless stream) against
  raw pyzmq ROUTER -> DEALER carrying the very same encoded bytes, measured
  in the same run, in two separate processes: on loopback, and across two
  network namespaces joined by a veth pair (real addresses, separate
  network stacks; skipped with the reason where namespaces cannot be made).
  Plain and CURVE. The receiver waits in the socket poll, so the figure is
  the transport's; the master's display loop (500 Hz by default) adds up
  to one period on top.
- Messages per second through the whole stack (a burst of lossless
  messages, each send waiting for room in the window).
- A slow receiver: it stops reading for 2 s while the sender sends 10,000
  lossless messages, then resumes. The window refuses what it cannot hold
  (the application is told); everything it accepted is delivered
  (``loopback.slow_receiver``: ``sent``, ``delivered``,
  ``refused_by_window``, ``lost``).

One-way latency needs one clock: both peers run on this host, and
CLOCK_MONOTONIC is one clock for every process and namespace of a kernel.
"""

from __future__ import annotations

import argparse
import datetime
import json
import platform
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from telethermal.jsonfile import write_json
from telethermal.netns import Namespaces
from telethermal.wire.codec import decode, encode
from telethermal.wire.golden import messages
from telethermal.wire.schema import MessageKind

N_LATENCY = 2000
INTERVAL_S = 0.001
N_THROUGHPUT = 20000
N_SLOW = 10000
SLOW_PAUSE_S = 2.0
PAYLOAD = {"contact_id": 3, "t_since_contact_s": 0.25,
           "classes": ["aluminium", "steel", "marble", "plexiglass", "graphite", "rubber",
                       "wood"],
           "posteriors": [0.01, 0.02, 0.03, 0.04, 0.1, 0.3, 0.5], "label": "wood",
           "confidence": 0.5, "decided": False, "reason": "", "object_temp_c": 24.5}


def codec_costs(repeats: int = 2000) -> dict:
    out = {}
    for kind, message in messages().items():
        wire = encode(message)
        t0 = time.perf_counter()
        for _ in range(repeats):
            encode(message)
        t1 = time.perf_counter()
        for _ in range(repeats):
            decode(wire)
        t2 = time.perf_counter()
        out[kind] = {"bytes": len(wire), "encode_us": (t1 - t0) / repeats * 1e6,
                     "decode_us": (t2 - t1) / repeats * 1e6}
    return out


# ------------------------------------------------------------------ peers
def _transport_config(args, role):
    from telethermal.wire.transport import TransportConfig
    return TransportConfig(host=args.host, bind_host=args.host, control_port=args.port,
                           stream_port=args.port + 1, security=args.security,
                           keys_dir=str(Path(args.keys) / role) if args.keys else None,
                           allowed_dir=str(Path(args.keys) / "allowed") if args.keys else None)


def _peer(args) -> None:
    """One side of a measurement, run as its own process."""
    import zmq

    from telethermal.wire.transport import Endpoint

    result = {}
    if args.stack == "e2e":
        endpoint = Endpoint("slave" if args.role == "sender" else "master",
                            _transport_config(args, "slave" if args.role == "sender" else
                                              "master"))
        end = time.monotonic() + 30
        while not endpoint.peer_alive and time.monotonic() < end:
            endpoint.poll(0.01)
        if args.role == "sender":
            for _ in range(3):                      # let the receiver settle
                endpoint.poll(0.05)
            for i in range(args.n):
                endpoint.send("material_estimate", **PAYLOAD)
                endpoint.poll(args.interval)
            t0 = time.monotonic()
            for i in range(args.burst):
                endpoint.send("material_estimate", wait_s=5.0, **PAYLOAD)
                if i % 100 == 0:
                    endpoint.poll(0.0)
            end = time.monotonic() + 20
            while endpoint.unacked and time.monotonic() < end:
                endpoint.poll(0.01)
            result["burst_s"] = time.monotonic() - t0
            result["unacked"] = endpoint.unacked
            endpoint.poll(0.3)
        else:
            lat, got, first_burst = [], 0, None
            end = time.monotonic() + 60
            while got < args.n + args.burst and time.monotonic() < end:
                for m in endpoint.poll(0.1):
                    if m["kind"] != MessageKind.MATERIAL_ESTIMATE:
                        continue
                    got += 1
                    if got <= args.n:
                        lat.append(time.monotonic() - m["sent_s"])
                    elif first_burst is None:
                        first_burst = time.monotonic()
            result.update(latency_s=lat, received=got, counters=endpoint.counters,
                          burst_recv_s=time.monotonic() - first_burst if first_burst else None)
            for _ in range(5):
                endpoint.poll(0.05)                 # acknowledge before leaving
        endpoint.close()
    elif args.stack == "slow":
        result = _slow_peer(args)
    else:
        ctx = zmq.Context.instance()
        wire = encode({"kind": "material_estimate", "v": 1, "seq": 1, "sent_s": 0.0, **PAYLOAD})
        if args.role == "sender":
            sock = ctx.socket(zmq.ROUTER)
            sock.linger = 0
            _raw_secure(sock, args, server=True)
            sock.bind(f"tcp://{args.host}:{args.port}")
            peer = sock.recv_multipart()[0]          # the receiver says hello
            time.sleep(0.1)
            for _ in range(args.n):
                sock.send_multipart([peer, np.float64(time.monotonic()).tobytes(), wire])
                time.sleep(args.interval)
            sock.recv_multipart()                    # done
            sock.close()
        else:
            sock = ctx.socket(zmq.DEALER)
            sock.linger = 0
            _raw_secure(sock, args, server=False)
            sock.connect(f"tcp://{args.host}:{args.port}")
            sock.send(b"hello")
            lat = []
            for _ in range(args.n):
                stamp, payload = sock.recv_multipart()
                lat.append(time.monotonic() - float(np.frombuffer(stamp, np.float64)[0]))
            sock.send(b"done")
            result["latency_s"] = lat
            time.sleep(0.1)
            sock.close()
    if args.out:
        Path(args.out).write_text(json.dumps(result))


def _slow_peer(args) -> dict:
    """The slow-receiver case: the sender (slave) sends ``args.burst``
    lossless messages without waiting, counting the window's refusals; the
    receiver (master) stops reading for ``SLOW_PAUSE_S`` at the first one,
    then reads until the stream has been quiet for 3 s."""
    from telethermal.errors import WindowFull
    from telethermal.wire.transport import Endpoint

    role = "slave" if args.role == "sender" else "master"
    endpoint = Endpoint(role, _transport_config(args, role))
    end = time.monotonic() + 30
    while not endpoint.peer_alive and time.monotonic() < end:
        endpoint.poll(0.01)
    if args.role == "sender":
        for _ in range(3):
            endpoint.poll(0.05)
        refused = 0
        for i in range(args.burst):
            try:
                endpoint.send("material_estimate", **PAYLOAD)
            except WindowFull:
                refused += 1
            if i % 100 == 0:
                endpoint.poll(0.0)
        end = time.monotonic() + 60
        while endpoint.unacked and time.monotonic() < end:
            endpoint.poll(0.01)
        result = {"sent": args.burst, "refused_by_window": refused, "unacked": endpoint.unacked,
                  "sender_counters": dict(endpoint.counters)}
        endpoint.poll(0.3)
    else:
        got, paused, last = 0, False, time.monotonic()
        end = time.monotonic() + 90
        while time.monotonic() < end:
            n = sum(m["kind"] == MessageKind.MATERIAL_ESTIMATE for m in endpoint.poll(0.05))
            if n:
                got, last = got + n, time.monotonic()
            if got and not paused:
                time.sleep(SLOW_PAUSE_S)            # the application stops reading
                paused = True
            if paused and time.monotonic() - last > 3.0:
                break
        result = {"delivered": got, "receiver_counters": dict(endpoint.counters)}
        for _ in range(5):
            endpoint.poll(0.05)
    endpoint.close()
    return result


def _run_peers(args: list[str], what: str, timeout_s: float,
               prefix=(None, None)) -> tuple[dict, dict]:
    """This module's ``--peer sender`` and ``--peer receiver`` with ``args``
    as two processes (each in its namespace of ``prefix``, if any); returns
    what each wrote (sender, receiver)."""
    with tempfile.TemporaryDirectory() as tmp:
        procs = []
        for role, ns in zip(("sender", "receiver"), prefix):
            cmd = [sys.executable, "-m", "telethermal.bench.transport", "--peer", role, *args,
                   "--out", str(Path(tmp) / f"{role}.json")]
            if ns:
                cmd = ["ip", "netns", "exec", ns] + cmd
            procs.append(subprocess.Popen(cmd, stdout=subprocess.DEVNULL,
                                          stderr=subprocess.PIPE, text=True))
        for p in procs:
            try:
                p.wait(timeout_s)
            except subprocess.TimeoutExpired:
                p.kill()
        errors = [p.stderr.read() for p in procs if p.returncode]
        if errors:
            raise RuntimeError(f"{what} peers failed: {errors[0][-800:]}")
        return tuple(json.loads((Path(tmp) / f"{role}.json").read_text())
                     for role in ("sender", "receiver"))


def _run_slow(host, port, n=N_SLOW) -> dict:
    """``loopback.slow_receiver``: the slow-receiver case in two processes."""
    sent, got = _run_peers(["--stack", "slow", "--security", "plain", "--host", host,
                            "--port", str(port), "--n", "0", "--burst", str(n)],
                           "slow receiver", 180)
    accepted = sent["sent"] - sent["refused_by_window"]
    return {"sent": sent["sent"], "delivered": got["delivered"],
            "refused_by_window": sent["refused_by_window"],
            "lost": accepted - got["delivered"], "unacked_at_end": sent["unacked"],
            "pause_s": SLOW_PAUSE_S, "resent": sent["sender_counters"]["resent"],
            "receiver": {k: got["receiver_counters"][k] for k in
                         ("gaps", "recovered", "duplicates", "out_of_window", "skipped")}}


def _raw_secure(sock, args, server):
    if args.security != "curve":
        return
    import zmq.auth
    if server:
        pub, sec = zmq.auth.load_certificate(str(Path(args.keys) / "slave" / "slave.key_secret"))
        sock.curve_publickey, sock.curve_secretkey, sock.curve_server = pub, sec, True
    else:
        pub, sec = zmq.auth.load_certificate(str(Path(args.keys) / "master" /
                                                  "master.key_secret"))
        sock.curve_publickey, sock.curve_secretkey = pub, sec
        sock.curve_serverkey = zmq.auth.load_certificate(str(Path(args.keys) / "master" /
                                                             "slave.key"))[0]


def _run_pair(stack, security, host, port, keys, prefix=(None, None), n=N_LATENCY,
              burst=N_THROUGHPUT) -> dict:
    args = ["--stack", stack, "--security", security, "--host", host, "--port", str(port),
            "--n", str(n), "--burst", str(burst if stack == "e2e" else 0),
            "--interval", str(INTERVAL_S)] + (["--keys", str(keys)] if keys else [])
    sent, got = _run_peers(args, f"{stack}/{security}", 120, prefix)
    lat = np.asarray(got["latency_s"]) * 1e6
    out = {"n": int(len(lat)), "p50_us": float(np.percentile(lat, 50)),
           "p99_us": float(np.percentile(lat, 99)), "max_us": float(lat.max())}
    if stack == "e2e":
        out["messages_per_s"] = burst / max(got["burst_recv_s"] or sent["burst_s"], 1e-9)
        out["lost_or_unacked"] = int(n + burst - got["received"]) + int(sent["unacked"])
        out["counters"] = got["counters"]
    return out


def run(progress=None, quick: bool = False) -> dict:
    """The codec's costs, each stack's latency on loopback and across two
    network namespaces, the slow receiver; ``quick``: a quarter of the
    messages per pair (a smoke run: its p99 rests on 5 messages)."""
    step = progress or (lambda _m: None)
    n, burst = (N_LATENCY // 4, N_THROUGHPUT // 4) if quick else (N_LATENCY, N_THROUGHPUT)
    report = {"codec": codec_costs()}
    with tempfile.TemporaryDirectory() as tmp:
        from telethermal.wire.keys import generate_link_keys
        keys = generate_link_keys(Path(tmp))
        step("loopback")
        from telethermal.ports import free_ports
        loop = {}
        for stack in ("raw", "e2e"):
            for security in ("plain", "curve"):
                loop[f"{stack}_{security}"] = _run_pair(stack, security, "127.0.0.1",
                                                        free_ports(1)[0], keys, n=n,
                                                        burst=burst)
        step("slow receiver")
        loop["slow_receiver"] = _run_slow("127.0.0.1", free_ports(1)[0])
        report["loopback"] = loop
        step("namespaces")
        reason = Namespaces.why_not()
        if reason is None:
            try:
                with Namespaces() as ns:
                    across = {"e2e_plain": "refused by design: plain only on loopback"}
                    for stack, security in (("raw", "plain"), ("raw", "curve"), ("e2e", "curve")):
                        # The sender binds in namespace a; the receiver connects from b.
                        across[f"{stack}_{security}"] = _run_pair(
                            stack, security, ns.addresses[0], 5600, keys, ns.names, n=n,
                            burst=burst)
                    across["curve_ratio_to_raw_zmq_p50"] = (across["e2e_curve"]["p50_us"] /
                                                            across["raw_curve"]["p50_us"])
                    report["namespaces"] = across
            except RuntimeError as exc:
                report["namespaces"] = {"skipped": str(exc)}
        else:
            report["namespaces"] = {"skipped": reason}
    lo = report["loopback"]
    report.update(
        e2e_p50_us=lo["e2e_plain"]["p50_us"], e2e_p99_us=lo["e2e_plain"]["p99_us"],
        raw_zmq_p50_us=lo["raw_plain"]["p50_us"],
        ratio_to_raw_zmq_p50=lo["e2e_plain"]["p50_us"] / lo["raw_plain"]["p50_us"],
        curve_e2e_p50_us=lo["e2e_curve"]["p50_us"], curve_e2e_p99_us=lo["e2e_curve"]["p99_us"],
        curve_ratio_to_raw_zmq_p50=lo["e2e_curve"]["p50_us"] / lo["raw_curve"]["p50_us"],
        messages_per_s=lo["e2e_plain"]["messages_per_s"],
        machine=f"{platform.node()} ({platform.machine()}, {platform.python_implementation()} "
                f"{platform.python_version()})",
        date=datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds"),
        payload="material_estimate, 7 classes", interval_s=INTERVAL_S, n=n)
    return report


def run_and_save(json_path, command: str = "", progress=None, quick: bool = False) -> dict:
    """Run the benchmark and write the JSON report (with ``command``);
    returns the report."""
    report = run(progress=progress, quick=quick)
    report["command"] = command
    write_json(json_path, report)
    return report


def main(argv=None):
    p = argparse.ArgumentParser()
    p.add_argument("--peer", choices=("sender", "receiver"), required=True, dest="role")
    p.add_argument("--stack", choices=("e2e", "raw", "slow"), required=True)
    p.add_argument("--security", choices=("plain", "curve"), default="plain")
    p.add_argument("--host", default="127.0.0.1")
    p.add_argument("--port", type=int, required=True)
    p.add_argument("--keys")
    p.add_argument("--n", type=int, default=N_LATENCY)
    p.add_argument("--burst", type=int, default=0)
    p.add_argument("--interval", type=float, default=INTERVAL_S)
    p.add_argument("--out")
    _peer(p.parse_args(argv))


if __name__ == "__main__":
    main()
