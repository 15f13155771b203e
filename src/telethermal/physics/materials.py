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


def _parse_row(row: dict[str, str], line: int) -> Material:
    try:
        values = [float(row[k]) for k in
                  ("conductivity_w_mk", "density_kg_m3", "specific_heat_j_kgk")]
    except (KeyError, TypeError, ValueError) as exc:
        raise ValueError(f"materials.csv line {line}: bad number ({exc})") from exc
    if not all(v > 0 and math.isfinite(v) for v in values):
        raise ValueError(f"materials.csv line {line}: properties must be positive and finite")
    return Material(row["name"].strip(), row["role"].strip(), *values, row["source"].strip())


@functools.cache
def load_materials() -> dict[str, Material]:
    """Read the shipped materials table, keyed by name."""
    text = resources.files("telethermal.physics").joinpath("materials.csv").read_text()
    lines = [ln for ln in text.splitlines() if ln and not ln.startswith("#")]
    rows = csv.DictReader(lines)
    return {m.name: m for m in (_parse_row(r, i + 2) for i, r in enumerate(rows))}


def get_material(name: str) -> Material:
    """Look a material up by name; the error lists the known names."""
    table = load_materials()
    try:
        return table[name]
    except KeyError as exc:
        known = ", ".join(sorted(table))
        raise UnknownMaterialError(
            f"unknown material {name!r}; known materials: {known}") from exc


def object_materials() -> list[str]:
    """Names of the materials a scene may place as objects."""
    return sorted(n for n, m in load_materials().items() if m.role == "object")
