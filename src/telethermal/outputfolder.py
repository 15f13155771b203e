"""The folder a command writes its results into: made if missing, and
refused with the reason and the fix when this process cannot write there
(a bind-mounted ``./out`` that the container engine made as root, or one
owned by another user), rather than a traceback half-way through a run."""

from __future__ import annotations

import os
from pathlib import Path

from telethermal.errors import OutputFolderError

FIX = ("if this runs in the compose demo, make ./out yourself (`mkdir -p out`) and run the "
       "container as its owner: `echo TELETHERMAL_UID=$(id -u) >> .env; echo "
       "TELETHERMAL_GID=$(id -g) >> .env` beside docker-compose.yml (docs/deployment.md); "
       "else choose another --out or chown the folder")


def _owner(path: Path) -> str:
    st = path.stat()
    return f"uid {st.st_uid} gid {st.st_gid}, mode {st.st_mode & 0o777:03o}"


def prepare_output_folder(path: str | os.PathLike) -> Path:
    """``path`` made (with its parents) and checked writable; raises
    :class:`OutputFolderError` naming the folder, its owner and this
    process's uid when it is not."""
    out = Path(path)
    me = f"uid {os.getuid()} gid {os.getgid()}"
    try:
        out.mkdir(parents=True, exist_ok=True)
    except PermissionError as exc:
        parent = next((p for p in out.parents if p.exists()), Path("/"))
        raise OutputFolderError(f"cannot create {out}: {parent} belongs to {_owner(parent)} "
                                f"and this process runs as {me}; {FIX}") from exc
    except OSError as exc:
        raise OutputFolderError(f"cannot create {out}: {exc.strerror}; {FIX}") from exc
    if not os.access(out, os.W_OK | os.X_OK):
        raise OutputFolderError(f"cannot write into {out}: it belongs to {_owner(out)} and "
                                f"this process runs as {me}; {FIX}")
    return out
