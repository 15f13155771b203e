"""What a decision says: its :class:`Label` and its :class:`Reason`.

Both stay the strings the wire and the recordings have always held:

* A :class:`Label` *is* its text, a ``str`` subclass: one material
  (``"steel"``), a group of materials the identifier is sure of together
  (``"aluminium|steel"``, members sorted, joined by :data:`GROUP_SEPARATOR`),
  :data:`UNKNOWN` (``"unknown"``), or :data:`NEW_MATERIAL` (``"new material"``:
  a touch outside every trained class, reported with its effusivity
  estimate; issue 30). It equals and hashes as that string, so
  it packs, prints, keys a dict and compares with a recorded label as the
  string did; code asks it :attr:`~Label.members`, :attr:`~Label.is_group`,
  :attr:`~Label.is_unknown` instead of splitting or spelling strings.
* A :class:`Reason` is a ``StrEnum`` whose values are the strings an
  estimate's ``reason`` (and a touch's report) carry.

Reading is tolerant: any string is a label (an old recording's, a peer's),
and a reason this version does not know stays the string it was.
"""

from __future__ import annotations

from enum import StrEnum
from typing import Iterable

GROUP_SEPARATOR = "|"
_UNKNOWN_TEXT = "unknown"
_NEW_TEXT = "new material"


class Label(str):
    """A decision's label: one material, a group of them, or unknown."""

    __slots__ = ()

    def __new__(cls, text: str = _UNKNOWN_TEXT) -> "Label":
        if type(text) is cls:
            return text
        if not isinstance(text, str):
            raise TypeError(f"a label is a string, got {type(text).__name__}")
        return super().__new__(cls, text)

    @classmethod
    def parse(cls, text: str) -> "Label":
        """The label a string (the wire's, a recording's) stands for."""
        return cls(text)

    @classmethod
    def of(cls, materials: Iterable[str]) -> "Label":
        """The label of these materials: one, or their group (sorted)."""
        names = sorted(materials)
        if not names:
            raise ValueError("a label needs at least one material")
        for name in names:
            if not name or GROUP_SEPARATOR in name or name in (_UNKNOWN_TEXT, _NEW_TEXT):
                raise ValueError(f"{name!r} cannot be a material of a label")
        return cls(GROUP_SEPARATOR.join(names))

    @property
    def is_unknown(self) -> bool:
        return self == _UNKNOWN_TEXT

    @property
    def is_new(self) -> bool:
        """A material outside every trained class (:data:`NEW_MATERIAL`): a
        decision, with its effusivity estimate, naming no class. Its one
        member is itself (the object memory keeps it as one more class),
        never a class of an identifier's (``within`` any classes: False)."""
        return self == _NEW_TEXT

    @property
    def members(self) -> tuple[str, ...]:
        """The materials it stands for: one, a group's (as written, sorted),
        none for unknown."""
        return () if self.is_unknown else tuple(self.split(GROUP_SEPARATOR))

    @property
    def is_group(self) -> bool:
        """More than one material (a pair the identifier is sure of)."""
        return GROUP_SEPARATOR in self

    @property
    def is_material(self) -> bool:
        """Exactly one material (a trained class's name, or a new material)."""
        return not self.is_unknown and GROUP_SEPARATOR not in self

    def holds(self, material: str) -> bool:
        """``material`` is (one of) what it stands for."""
        return material in self.members

    def within(self, classes: Iterable[str]) -> bool:
        """Not unknown, and every material it stands for is one of ``classes``."""
        known = set(classes)
        return not self.is_unknown and all(m in known for m in self.members)


#: The label of "no material": the answer rather than a guess.
UNKNOWN = Label(_UNKNOWN_TEXT)
#: The label of a touch outside every trained class, its effusivity
#: estimated (an estimate's ``effusivity_*`` fields): not a class of any
#: identifier (``Label.of`` refuses it as a material's name).
NEW_MATERIAL = Label(_NEW_TEXT)


class Reason(StrEnum):
    """Why an estimate is what it is (its ``reason``); the values are the
    strings the wire and recordings hold."""

    UNDECIDED = ""                              # not committed yet
    CONFIDENT = "confident"                     # one class passed the threshold
    CONFIDENT_GROUP = "confident group"         # two together did; may be refined
    OUTSIDE_CLASSES = "outside classes"         # unknown: unlike every learnt class
    NEW_MATERIAL = "new material"               # new material: its estimate outside every class
    GAP_TOO_SMALL = "gap too small"             # unknown: too little heat exchanged
    NOT_CONFIDENT = "not confident"             # unknown: the last window unconvinced
    FORCE_OUTSIDE = "force outside trained range"   # unknown: a touch unlike the trained
    OBJECT_MEMORY = "object memory"             # recalled, not sensed
    BOARD_LOST = "sensor board lost"            # unknown: the board went silent
    NO_OBJECT_TEMPERATURE = "no object temperature"     # unknown: its thermometer refused
    # unknown: the pad model's fit leaves a residual past what the noise allows
    PAD_MODEL_MISFIT = "pad model does not fit: recalibrate"
    # named by the model's model-free fallback (``Identifier.fallback_``) after the misfit
    PAD_MODEL_FALLBACK = "pad model does not fit: named by the fallback"
    # A touch's report only (no estimate carries these):
    NO_ESTIMATE = "no estimate"
    NO_DECISION = "no decision"
    SLAVE_RESTARTED = "slave restarted"
