"""MkDocs hooks: pages kept beside the code they describe, served as they are.

The two-host guide (``deploy/README.md``, run as written by its test), the
protocol (``proto/``, the conformance suite's source) and the benchmark page
(``bench/report.md``, written by ``telethermal bench report`` from
``bench/results/``, the one place with dated figures) each keep a single
copy: the site reads them from where they live instead of holding a copy
that would drift.
"""

from __future__ import annotations

from pathlib import Path

from mkdocs.structure.files import File, Files

ROOT = Path(__file__).resolve().parent

#: (file in the repository, its page or asset in the site)
OUTSIDE = [
    ("deploy/README.md", "two-hosts.md"),
    ("proto/README.md", "proto/index.md"),
    ("proto/PROTOCOL.md", "proto/PROTOCOL.md"),
    ("proto/SERIAL.md", "proto/SERIAL.md"),
    ("proto/CAN.md", "proto/CAN.md"),
    ("proto/peltier.dbc", "proto/peltier.dbc"),
    ("firmware/README.md", "firmware/index.md"),
    ("bench/report.md", "benchmarks/index.md"),
    ("bench/transport.png", "benchmarks/transport.png"),
]


def _outside_files() -> list[tuple[Path, str]]:
    pairs = [(ROOT / src, dest) for src, dest in OUTSIDE]
    pairs += [(png, f"benchmarks/results/{png.name}")
              for png in sorted((ROOT / "bench" / "results").glob("*.png"))]
    return pairs


def on_files(files: Files, config) -> Files:
    for path, dest in _outside_files():
        if not path.is_file():
            raise FileNotFoundError(f"mkdocs_hooks.py: {path.relative_to(ROOT)} is missing "
                                    f"(the site's page {dest})")
        files.append(File.generated(config, dest, abs_src_path=str(path)))
    return files
