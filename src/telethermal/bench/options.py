"""Which options of a bench's command change what it measures: the
benchmark page calls a run with any of them reduced."""

from __future__ import annotations

import shlex


#: Options that say where a bench writes, where and on how many workers it
#: runs, or where it reads the models it would otherwise train (``--models``:
#: the same files; the JSON's ``models`` says which), not what it measures.
OUTPUT_OPTIONS = frozenset({"--json", "--png", "--jobs", "--executor", "--models"})
#: Options at the value the issue's targets name: which bench, not a
#: reduction of it (``bench identify --as-built 0.15``, its 5 pads).
TARGET_OPTIONS = frozenset({"--as-built 0.15", "--pads 5"})
#: Options that choose another setting to compare, not a smaller run
#: (``--references aluminium,steel,wood``: other reference blocks).
SETTING_OPTIONS = frozenset({"--references"})


def off_defaults(command: str) -> tuple[list[str], list[str]]:
    """:func:`reduced_options` of ``command`` split in two: the reductions
    (fewer seeds, methods, ...) and the other settings
    (:data:`SETTING_OPTIONS`)."""
    from telethermal.ident.calibration import REFERENCE_MATERIALS

    off = reduced_options(command)
    settings = [o for o in off if o.split("=")[0].split()[0] in SETTING_OPTIONS]
    reduced = [o for o in off if o not in settings]
    # The default reference blocks named explicitly (in any order): the default.
    default = sorted(REFERENCE_MATERIALS)
    settings = [o for o in settings
                if sorted(o.replace("=", " ").split(" ", 1)[-1].split(",")) != default]
    return reduced, settings


def reduced_options(command: str) -> list[str]:
    """The options of a bench's ``command`` (as stored in its JSON) that
    change what it measures (``--quick``, ``--seeds 2``, ``--methods a,b``):
    none for a run at the bench's defaults."""
    try:
        words = shlex.split(command)
    except ValueError:                  # an unbalanced quote: read it word by word
        words = command.split()
    out = []
    for i, word in enumerate(words):
        if not word.startswith("--"):
            continue
        name = word.split("=", 1)[0]
        if name in OUTPUT_OPTIONS:
            continue
        value = words[i + 1] if "=" not in word and i + 1 < len(words) else ""
        option = word if "=" in word or not value or value.startswith("--") \
            else f"{word} {value}"
        if option.replace("=", " ") not in TARGET_OPTIONS:
            out.append(option)
    return out


def parse_methods(text: str) -> list[str]:
    """``--methods a,b``: the names, each a method of the registry
    (BenchError naming an unknown or empty one, before any work)."""
    from telethermal.errors import BenchError
    from telethermal.ident.registry import METHODS

    names = [m.strip() for m in text.split(",")]
    bad = [m for m in names if m not in METHODS]
    if bad or not names:
        raise BenchError(f"--methods {text!r}: {', '.join(repr(m) for m in bad) or 'none'} "
                         f"not a method; methods: {', '.join(sorted(METHODS))}")
    return list(dict.fromkeys(names))
