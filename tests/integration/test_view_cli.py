"""``telethermal view`` as a user starts it: the address printed at start,
the page and its recordings served, a clean stop on SIGTERM."""

import json
import re
import signal
import subprocess
import sys
import urllib.request

from telethermal.cli import build_parser


def test_view_command_serves_and_stops_cleanly(tmp_path):
    (tmp_path / "a.mcap").write_bytes(b"not a recording")
    proc = subprocess.Popen([sys.executable, "-m", "telethermal", "view", "--recordings",
                             str(tmp_path), "--port", "0"], stdout=subprocess.PIPE, text=True)
    try:
        line = proc.stdout.readline()
        url = re.search(r"http://127\.0\.0\.1:\d+/", line).group(0)
        with urllib.request.urlopen(url + "api/info", timeout=10) as resp:
            info = json.load(resp)
        assert info == {"live": False, "recordings": ["a.mcap"], "message": ""}
        with urllib.request.urlopen(url, timeout=10) as resp:
            assert b"telethermal view" in resp.read()
    finally:
        proc.send_signal(signal.SIGTERM)
        code = proc.wait(10)
        proc.stdout.close()
    assert code == 0


def test_demo_view_option_and_its_default_port():
    parser = build_parser()
    assert parser.parse_args(["demo", "--view"]).view == 8050
    assert parser.parse_args(["demo", "--view", "0"]).view == 0
    assert parser.parse_args(["demo"]).view is None
    assert parser.parse_args(["view"]).port == 8050
