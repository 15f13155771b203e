"""Errors are told apart by their class, not their text, and keep their
cause: an unknown message kind is an UnknownKindError on both sides of the
codec; a wrapped error carries the lower one on ``__cause__`` (its errno,
its type) rather than dropping it (``raise ... from None``)."""

import tomllib

import msgpack
import pytest

from telethermal.errors import ProtocolError, TransportError, UnknownKindError
from telethermal.services.config import ConfigError, load_config
from telethermal.wire.codec import decode
from telethermal.wire.transport import Endpoint, TransportConfig

PLAIN = TransportConfig(security="plain", control_port=0, stream_port=0)


@pytest.fixture
def slave():
    endpoint = Endpoint("slave", PLAIN)
    yield endpoint
    endpoint.close()


def test_sending_an_unknown_kind_is_an_unknown_kind_error(slave):
    with pytest.raises(UnknownKindError, match="unknown message kind 'no_such_kind'"):
        slave.send("no_such_kind")
    # Still a ProtocolError for callers that only know the base class.
    assert issubclass(UnknownKindError, ProtocolError)


def test_receiving_an_unknown_kind_is_an_unknown_kind_error():
    data = msgpack.packb({"kind": "no_such_kind", "v": 1, "seq": 1, "sent_s": 0.0})
    with pytest.raises(UnknownKindError):
        decode(data)
    with pytest.raises(ProtocolError) as info:
        decode(b"\xc1")                         # not msgpack: a ProtocolError, not unknown kind
    assert not isinstance(info.value, UnknownKindError)
    assert info.value.__cause__ is not None     # msgpack's own error kept


def test_a_config_error_names_file_and_table_once_and_keeps_its_cause(tmp_path):
    path = tmp_path / "slave.toml"
    path.write_text('[slave]\ndevices = "bogus"\n')
    with pytest.raises(ConfigError) as info:
        load_config(path, "slave")
    assert str(info.value).count(str(path)) == 1
    assert str(info.value).startswith(f"{path} [slave]: devices must be")
    assert isinstance(info.value.__cause__, ConfigError)     # the class's own check
    path.write_text('[slave]\nno_such_key = 1\n')
    with pytest.raises(ConfigError) as info:
        load_config(path, "slave")
    assert str(info.value).count(str(path)) == 1             # named by table_values alone
    path.write_text("[slave\n")
    with pytest.raises(ConfigError) as info:
        load_config(path, "slave")
    assert isinstance(info.value.__cause__, tomllib.TOMLDecodeError)


def test_a_port_in_use_keeps_the_zmq_error_and_its_errno(slave):
    import zmq

    taken = TransportConfig(security="plain", control_port=slave.ports[0], stream_port=0)
    with pytest.raises(TransportError) as info:
        Endpoint("slave", taken)
    assert isinstance(info.value.__cause__, zmq.ZMQError)
    assert info.value.__cause__.errno == zmq.EADDRINUSE
