"""Two Linux network namespaces joined by a veth pair, for tests and
benchmarks that need real addresses and separate network stacks on one
machine. Created and removed by the caller (root and iproute2 needed)."""

from __future__ import annotations

import os
import shutil
import subprocess

class Namespaces:
    """Two network namespaces joined by a veth pair; removed on exit."""

    def __init__(self, tag: str = "tt"):
        suffix = f"{os.getpid() % 100000}"
        self.names = (f"{tag}a{suffix}", f"{tag}b{suffix}")
        self.addresses = ("10.231.0.1", "10.231.0.2")

    @staticmethod
    def why_not() -> str | None:
        if os.geteuid() != 0:
            return "network namespaces need root"
        if shutil.which("ip") is None:
            return "the ip command (iproute2) is not installed"
        return None

    def __enter__(self):
        a, b = self.names
        va, vb = f"v{a}", f"v{b}"
        steps = [["ip", "netns", "add", a], ["ip", "netns", "add", b],
                 ["ip", "link", "add", va, "type", "veth", "peer", "name", vb],
                 ["ip", "link", "set", va, "netns", a], ["ip", "link", "set", vb, "netns", b],
                 ["ip", "-n", a, "addr", "add", f"{self.addresses[0]}/30", "dev", va],
                 ["ip", "-n", b, "addr", "add", f"{self.addresses[1]}/30", "dev", vb],
                 ["ip", "-n", a, "link", "set", va, "up"], ["ip", "-n", b, "link", "set", vb, "up"],
                 ["ip", "-n", a, "link", "set", "lo", "up"], ["ip", "-n", b, "link", "set", "lo", "up"]]
        for step in steps:
            r = subprocess.run(step, capture_output=True, text=True)
            if r.returncode:
                self.__exit__(None, None, None)
                raise RuntimeError(f"{' '.join(step)}: {r.stderr.strip()}")
        return self

    def __exit__(self, *exc):
        for ns in self.names:
            subprocess.run(["ip", "netns", "del", ns], capture_output=True)
        return False


