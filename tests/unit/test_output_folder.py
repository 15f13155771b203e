"""``telethermal demo --out`` into a folder this process cannot write: one
clear line with the owner, this process's uid and the fix, exit code 2, no
traceback (issue 28: the compose demo's ``./out`` made by the engine as
root while the container runs as uid 1000)."""

import os
import select
import shutil
import signal
import sys
import time
import tempfile
import traceback
from pathlib import Path

import pytest

from telethermal.cli import main
from telethermal.errors import OutputFolderError
from telethermal.outputfolder import prepare_output_folder

NOBODY = 65534


def test_a_missing_folder_is_made(tmp_path):
    out = prepare_output_folder(tmp_path / "a" / "b")
    assert out.is_dir()


def test_a_file_in_the_way_is_refused_with_the_fix(tmp_path):
    (tmp_path / "out").write_text("")
    with pytest.raises(OutputFolderError, match="cannot create .*TELETHERMAL_UID"):
        prepare_output_folder(tmp_path / "out" / "demo")


@pytest.fixture
def root_owned_folder():
    """A folder as the engine makes a missing bind mount: root's, mode 755,
    in a world-traversable place."""
    if os.geteuid() != 0:
        pytest.skip("needs root, to run the command as another user")
    top = Path(tempfile.mkdtemp(prefix="telethermal-out-"))
    top.chmod(0o755)
    (top / "out").mkdir(mode=0o755)
    yield top / "out"
    shutil.rmtree(top)


def _as_user(uid: int, argv: list[str], guard_s: float = 120.0) -> tuple[int, str]:
    """``telethermal ARGV`` in a forked child running as ``uid``: its exit
    code and what it printed (the interpreter's files need not be readable
    by that user: everything is imported already)."""
    read_fd, write_fd = os.pipe()
    pid = os.fork()
    if pid == 0:                                   # the child
        code = 99
        try:
            os.close(read_fd)
            os.dup2(write_fd, 1)
            os.dup2(write_fd, 2)
            sys.stdout = os.fdopen(1, "w")         # not pytest's capture
            sys.stderr = os.fdopen(2, "w")
            os.setgroups([])
            os.setgid(uid)
            os.setuid(uid)
            code = main(argv)
        except BaseException:                      # noqa: BLE001 - reported to the parent
            traceback.print_exc()
        finally:
            sys.stdout.flush()
            sys.stderr.flush()
            os._exit(code)
    os.close(write_fd)
    # A hang guard (not a timing): a child forked from this threaded worker
    # that deadlocks (a lock another thread held at the fork) is killed and
    # the test fails saying so, instead of a read that waits for ever.
    text, deadline = b"", time.monotonic() + guard_s
    with os.fdopen(read_fd, "rb") as pipe:
        while (left := deadline - time.monotonic()) > 0:
            if select.select([pipe], [], [], left)[0]:
                chunk = os.read(pipe.fileno(), 65536)
                if not chunk:
                    break
                text += chunk
        else:
            os.kill(pid, signal.SIGKILL)
            os.waitpid(pid, 0)
            pytest.fail(f"the child as uid {uid} did not end within {guard_s} s: "
                        f"{text.decode(errors='replace')[-2000:]}")
    return os.waitstatus_to_exitcode(os.waitpid(pid, 0)[1]), text.decode(errors="replace")


@pytest.mark.parametrize("target", ["demo", "."])
def test_the_demo_as_another_user_says_whose_folder_it_is(root_owned_folder, target):
    code, text = _as_user(NOBODY, ["demo", "--out", str(root_owned_folder / target)])
    text = " ".join(text.split())                  # as rich wrapped it
    assert code == 2, text
    assert "Traceback" not in text
    assert "uid 0 gid 0" in text and f"runs as uid {NOBODY}" in text
    assert "TELETHERMAL_UID" in text
