"""free_ports: distinct ports, bindable, never from the range the kernel
picks from itself (where a connection's own end or another program's
bind(0) could take one before the service binds it)."""

import socket

import pytest

from telethermal import ports


def test_ports_are_distinct_bindable_and_outside_the_ephemeral_range():
    first, last = ports.ephemeral_range()
    got = ports.free_ports(6)
    assert len(set(got)) == 6
    for p in got:
        assert not first <= p <= last and p >= ports.LOWEST_PORT
        with socket.socket() as s:
            s.bind(("127.0.0.1", p))


def test_a_port_someone_listens_on_is_never_given(monkeypatch):
    # Only two candidates outside the range: the one held and one more.
    with socket.socket() as held:
        held.bind(("127.0.0.1", 0))
        taken = held.getsockname()[1]
        monkeypatch.setattr(ports, "LOWEST_PORT", taken)
        monkeypatch.setattr(ports, "ephemeral_range", lambda: (taken + 2, 65535))
        for _ in range(20):
            assert ports.free_ports(1) != [taken]


def test_no_room_outside_the_range_falls_back_to_the_kernels_choice(monkeypatch):
    monkeypatch.setattr(ports, "ephemeral_range", lambda: (1, 65535))
    got = ports.free_ports(3)
    assert len(set(got)) == 3 and all(p > 0 for p in got)


@pytest.mark.parametrize("text, expected", [("32768\t60999\n", (32768, 60999)),
                                            ("1024 65535", (1024, 65535)),
                                            ("garbage", ports.DEFAULT_EPHEMERAL)])
def test_the_kernels_range_is_read_from_its_file(tmp_path, text, expected):
    f = tmp_path / "range"
    f.write_text(text)
    assert ports.ephemeral_range(str(f)) == expected


def test_a_missing_range_file_gives_the_linux_default(tmp_path):
    assert ports.ephemeral_range(str(tmp_path / "absent")) == ports.DEFAULT_EPHEMERAL


def test_kernel_ports_are_distinct_and_from_the_ephemeral_range():
    first, last = ports.ephemeral_range()
    for _ in range(50):
        got = ports.kernel_ports(3)
        assert len(set(got)) == 3 and all(first <= p <= last for p in got)
