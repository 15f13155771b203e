"""The materials table: thermal properties read from ``materials.csv``.

Effusivity ``sqrt(k * rho * c)`` and diffusivity ``k / (rho * c)`` are derived
here, never typed into the table.
"""

from __future__ import annotations

import csv
import functools
import math
from dataclasses import dataclass
from importlib import resources

from telethermal.errors import UnknownMaterialError


@dataclass(frozen=True, slots=True)
class Material:
    """Thermal properties of one material (SI units)."""

    name: str
    role: str
    conductivity_w_mk: float
    density_kg_m3: float
    specific_heat_j_kgk: float
    source: str

    @property
    def volumetric_heat_j_m3k(self) -> float:
        """rho * c, J/(m^3 K)."""
        return self.density_kg_m3 * self.specific_heat_j_kgk

    @property
    def diffusivity_m2_s(self) -> float:
        """alpha = k / (rho c), m^2/s."""
        return self.conductivity_w_mk / self.volumetric_heat_j_m3k

    @property
    def effusivity(self) -> float:
        """e = sqrt(k rho c), W s^0.5 / (m^2 K)."""
        return math.sqrt(self.conductivity_w_mk * self.volumetric_heat_j_m3k)

    def scaled(self, conductivity: float = 1.0, heat: float = 1.0) -> "Material":
        """A copy with k and rho*c multiplied (trial-to-trial variability)."""
        return Material(self.name, self.role, self.conductivity_w_mk * conductivity,
                        self.density_kg_m3 * heat, self.specific_heat_j_kgk, self.source)


COLUMNS = ("name", "role", "conductivity_w_mk", "density_kg_m3", "specific_heat_j_kgk",
           "source")
ROLES = ("object", "skin", "pad", "fluid")


def _parse_row(row: dict[str, str], line: int, where: str = "materials.csv") -> Material:
    missing = [c for c in COLUMNS if not (row.get(c) or "").strip()]
    if missing:
        raise ValueError(f"{where} line {line}: empty or missing {', '.join(missing)}")
    values = []
    for k in ("conductivity_w_mk", "density_kg_m3", "specific_heat_j_kgk"):
        try:
            values.append(float(row[k]))
        except ValueError:
            raise ValueError(f"{where} line {line}, column {k!r}: {row[k]!r} is not a "
                             f"number") from None
        if not (values[-1] > 0 and math.isfinite(values[-1])):
            raise ValueError(f"{where} line {line}, column {k!r}: {row[k]!r} must be positive "
                             f"and finite")
    if row["role"].strip() not in ROLES:
        raise ValueError(f"{where} line {line}, column 'role': {row['role']!r}; roles: "
                         f"{', '.join(ROLES)}")
    return Material(row["name"].strip(), row["role"].strip(), *values, row["source"].strip())


def read_table(text: str, where: str) -> dict[str, Material]:
    """A materials table (the package's columns; ``#`` lines are comments)."""
    numbered = [(i, ln) for i, ln in enumerate(text.lstrip("\ufeff").splitlines(), start=1)
                if ln.strip() and not ln.startswith("#")]
    rows = csv.DictReader([ln for _, ln in numbered])
    missing = [c for c in COLUMNS if c not in (rows.fieldnames or [])]
    if missing:
        raise ValueError(f"{where}: missing column(s) {', '.join(missing)}; a materials table "
                         f"has {', '.join(COLUMNS)}")
    table: dict[str, Material] = {}
    for k, r in enumerate(rows, start=1):
        line = numbered[k][0]                      # the file's line (comments counted)
        m = _parse_row(r, line, where)
        if m.name in table:
            raise ValueError(f"{where} line {line}: material {m.name!r} appears twice")
        table[m.name] = m
    return table


@functools.cache
def load_materials() -> dict[str, Material]:
    """The package's materials table, keyed by name (a scene's own come
    through :func:`register_materials`; :func:`get_material` reads both)."""
    text = resources.files("telethermal.physics").joinpath("materials.csv").read_text()
    return read_table(text, "materials.csv")


#: Materials scene files brought (their ``materials`` table), by name: the
#: material and the table that defined it. They add to the package's table
#: or shadow its rows, for this process.
_SCENE_MATERIALS: dict[str, tuple[Material, str]] = {}
#: Package rows this process has looked up: a table may no longer shadow them
#: (what used them would silently change).
_PACKAGE_USED: set[str] = set()


def register_materials(table: dict[str, Material], source: str) -> list[str]:
    """A scene's own materials, for this process. A material another table
    defined differently is refused (one process, one definition of a name),
    and so is a shadow of a package row this process has already used.
    Returns the names it added (those already held, identical, excluded)."""
    for name, m in table.items():
        held = _SCENE_MATERIALS.get(name)
        if held is not None and held[0] != m:
            raise ValueError(f"{source}: material {name!r} is defined differently by "
                             f"{held[1]}, loaded before in this process: one process holds one "
                             f"definition of a material (run the scenes in separate processes)")
        if held is None and name in _PACKAGE_USED and load_materials()[name] != m:
            raise ValueError(f"{source}: material {name!r} shadows the package's row, which "
                             f"this process has already used (another scene's): run the "
                             f"scenes in separate processes")
    added = [name for name in table if name not in _SCENE_MATERIALS]
    for name in added:
        _SCENE_MATERIALS[name] = (table[name], source)
    return added


def unregister_materials(names) -> None:
    """Forget ``names`` (what a scene that did not load registered)."""
    for name in names:
        _SCENE_MATERIALS.pop(name, None)


def shadowed_by(name: str) -> str | None:
    """The table that redefined the package's ``name`` in this process, if any."""
    held = _SCENE_MATERIALS.get(name)
    return held[1] if held is not None and name in load_materials() else None


def get_material(name: str) -> Material:
    """Look a material up by name (a scene's own table first, then the
    package's); the error lists the known names."""
    held = _SCENE_MATERIALS.get(name)
    if held is not None:
        return held[0]
    table = load_materials()
    try:
        material = table[name]
        _PACKAGE_USED.add(name)
        return material
    except KeyError as exc:
        known = ", ".join(sorted(set(table) | set(_SCENE_MATERIALS)))
        raise UnknownMaterialError(
            f"unknown material {name!r}; known materials: {known}") from exc


def object_materials() -> list[str]:
    """Names of the materials a scene may place as objects."""
    # (read directly: listing the rows is not using them, see _PACKAGE_USED)
    table = {**load_materials(), **{n: m for n, (m, _) in _SCENE_MATERIALS.items()}}
    return sorted(n for n, m in table.items() if m.role == "object")
