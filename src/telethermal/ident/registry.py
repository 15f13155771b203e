"""Identification methods by name, and loading a saved model of any method."""

from __future__ import annotations

from pathlib import Path

from telethermal.errors import IdentificationError, ModelFileError
from telethermal.ident.base import Identifier, read_model_file
from telethermal.ident.methods import EffusivityLda, PcaFnn
from telethermal.ident.recurrent import Lstm, Rnn

METHODS: dict[str, type[Identifier]] = {m.method: m for m in (PcaFnn, EffusivityLda, Lstm,
                                                                Rnn)}


def make(method: str, **kw) -> Identifier:
    try:
        return METHODS[method](**kw)
    except KeyError:
        raise IdentificationError(f"unknown method {method!r}; methods: "
                                  f"{', '.join(sorted(METHODS))}") from None


def load_model(path: str | Path) -> Identifier:
    header, arrays = read_model_file(path)
    cls = METHODS.get(header.get("method"))
    if cls is None:
        raise ModelFileError(f"{path}: method {header.get('method')!r} is not one this "
                             f"telethermal knows ({', '.join(sorted(METHODS))})")
    return cls.restore(header, arrays)
