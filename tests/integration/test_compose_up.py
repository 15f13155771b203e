"""docker-compose.yml brought up for real (marker ``compose``): a base image
made from Debian's packages (mmdebstrap, docker import: no registry of
images is needed), a wheelhouse filled by the host's pip, the project's
image built from it with no network (from this checkout's sources, every
run), then ``up``, a touch through ``exec``,
``down`` mid-touch, the demo profile and ``down``.

Network: every packet stays on the containers' own loopback. A compose
override gives the slave ``network_mode: none`` (the master joins its
namespace, as in docker-compose.yml), and a ``dockerd`` this test starts
runs with ``--bridge=none --iptables=false``; the host reaches the services
only through ``exec``.

Skips, saying why, when no engine can be had (no docker client, no
``dockerd`` to start, not root, no mmdebstrap); ``TELETHERMAL_REQUIRE_DOCKER=1``
makes that a failure. Each stage's wall time is printed at the end.

Work kept between runs, none of it from the sources: the base image (in the
engine), the wheelhouse (under ``$XDG_CACHE_HOME/telethermal``, default
``~/.cache/telethermal``, one folder per set of dependencies; delete it to
download again) and the image's dependency layers (the engine's layer
cache: deploy/Dockerfile installs the dependencies before it reads src/).
The image itself is built every run, and a test checks that it holds this
checkout's sources."""

from __future__ import annotations

import hashlib
import json
import os
import re
import shutil
import subprocess
import sys
import sysconfig
import tempfile
import time
import tomllib
from pathlib import Path

import pytest
import yaml

from realclock import stalled

from telethermal.record.recording import read_recording

# The hang guard (pyproject.toml's 15 minutes) is longer here: the first run
# on a machine builds the base image from Debian's packages and every
# dependency layer before the first test (module fixtures count in the guard).
pytestmark = [pytest.mark.compose, pytest.mark.timeout(2700)]
#: The warnings a stalled display loop causes (tests/realclock.py).
STALL_WARNING = re.compile(r"safe state entered: surface out of band|link lost mid-contact")

ROOT = Path(__file__).resolve().parents[2]
BASE = "telethermal-test-base:bookworm"
IMAGE = "telethermal:compose-test"
PROJECT = "telethermaltest"
#: What the image's build context needs (the .dockerignore allow-list) and
#: what compose reads.
CONTEXT = ["pyproject.toml", "constraints.txt", "README.md", "src", "deploy/Dockerfile",
           "deploy/compose", "deploy/check-no-cuda.sh", "deploy/wheels/README.md",
           "docker-compose.yml", ".dockerignore"]


def _unavailable(reason: str):
    if os.environ.get("TELETHERMAL_REQUIRE_DOCKER") == "1":
        pytest.fail(f"TELETHERMAL_REQUIRE_DOCKER=1 but {reason}")
    pytest.skip(reason)


def _run(argv, timeout_s: float, check: bool = True, **kw) -> subprocess.CompletedProcess:
    r = subprocess.run(argv, capture_output=True, text=True, timeout=timeout_s,
                       stdin=subprocess.DEVNULL, **kw)
    if check and r.returncode != 0:
        raise AssertionError(f"{' '.join(map(str, argv))}: exit {r.returncode}\n"
                             f"{r.stdout[-4000:]}\n{r.stderr[-4000:]}")
    return r


class Timings(dict):
    def stage(self, name: str):
        timings, t0 = self, time.monotonic()

        class _Stage:
            def __enter__(self):
                return self

            def __exit__(self, *exc):
                timings[name] = time.monotonic() - t0
        return _Stage()


@pytest.fixture(scope="module")
def timings(pytestconfig):
    t = Timings()
    t0 = time.monotonic()
    yield t
    t["whole compose test"] = time.monotonic() - t0
    reporter = pytestconfig.pluginmanager.get_plugin("terminalreporter")
    capture = pytestconfig.pluginmanager.get_plugin("capturemanager")
    if reporter is not None and capture is not None and t:
        # A pytest-xdist worker's reporter prints nowhere; its stderr is the
        # run's own.
        write = reporter.write_line if "PYTEST_XDIST_WORKER" not in os.environ else \
            (lambda line: print(line, file=sys.stderr, flush=True))
        with capture.global_and_fixture_disabled():       # into the CI log
            write("")
            for name, seconds in t.items():
                write(f"compose: {name}: {seconds:.1f} s")


def _engine_answers() -> bool:
    try:
        return _run(["docker", "info"], 20, check=False).returncode == 0
    except subprocess.TimeoutExpired:
        return False


@pytest.fixture(scope="module")
def engine(tmp_path_factory, timings):
    """A Docker engine: the running one, or a ``dockerd`` started here (no
    bridge, no iptables) and stopped at the end by its PID."""
    if shutil.which("docker") is None:
        _unavailable("no docker client (apt-get install docker.io)")
    compose = ["docker-compose"] if shutil.which("docker-compose") else None
    if compose is None and _run(["docker", "compose", "version"], 20,
                                check=False).returncode == 0:
        compose = ["docker", "compose"]
    if compose is None:
        _unavailable("no compose client (apt-get install docker-compose)")
    free_gb = shutil.disk_usage("/var/lib" if Path("/var/lib").is_dir() else "/").free / 1e9
    if free_gb < 8:
        _unavailable(f"{free_gb:.1f} GB free on the engine's disk; the images and their "
                     "build need about 8")
    if _engine_answers():
        yield compose
        return
    if shutil.which("dockerd") is None or os.geteuid() != 0:
        _unavailable("no Docker engine runs, and this test cannot start one (needs dockerd "
                     "and root)")
    log = tmp_path_factory.mktemp("dockerd") / "dockerd.log"
    with timings.stage("dockerd started"), open(log, "w") as out:
        proc = subprocess.Popen(["dockerd", "--bridge=none", "--iptables=false",
                                 "--ip6tables=false"], stdout=out, stderr=subprocess.STDOUT,
                                start_new_session=True)
        end = time.monotonic() + 60
        while not _engine_answers():
            if proc.poll() is not None or time.monotonic() > end:
                proc.kill()
                proc.wait()
                _unavailable(f"dockerd did not start: {log.read_text()[-2000:]}")
            time.sleep(0.5)
    try:
        yield compose
    finally:
        proc.terminate()
        try:
            proc.wait(timeout=30)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()


def _image_exists(name: str) -> bool:
    return _run(["docker", "image", "inspect", name], 20, check=False).returncode == 0


@pytest.fixture(scope="module")
def base_image(engine, tmp_path_factory, timings):
    """Debian bookworm's python3 and python3-venv as an image, from Debian's
    packages (no image registry needed); kept between runs."""
    if _image_exists(BASE):
        return BASE
    if shutil.which("mmdebstrap") is None:
        _unavailable("no mmdebstrap to build the base image (apt-get install mmdebstrap)")
    tar = tmp_path_factory.mktemp("base") / "base.tar"
    with timings.stage("base image built (mmdebstrap + docker import)"):
        _run(["mmdebstrap", "--variant=minbase", "--include=python3,python3-venv",
              "bookworm", str(tar)], 300)
        _run(["docker", "import", "--change",
              "ENV PATH=/usr/local/sbin:/usr/local/bin:/usr/sbin:/usr/bin:/sbin:/bin",
              str(tar), BASE], 120)
    tar.unlink()
    return BASE


def _copy_context(dest: Path) -> None:
    for rel in CONTEXT:
        src, dst = ROOT / rel, dest / rel
        dst.parent.mkdir(parents=True, exist_ok=True)
        if src.is_dir():
            shutil.copytree(src, dst, ignore=shutil.ignore_patterns(
                "__pycache__", "*.pyc", "*.egg-info", "*.whl"))
        else:
            shutil.copy2(src, dst)


TORCH = "torch==2.13.0"


def _requirements() -> list[str]:
    """What the wheelhouse must hold: the project's dependencies (as
    deploy/Dockerfile installs them) and its build requirements."""
    project = tomllib.loads((ROOT / "pyproject.toml").read_text())
    return [*project["project"]["dependencies"], *project["build-system"]["requires"]]


def _wheelhouse_dir() -> Path:
    """The wheelhouse's folder in the user's cache, named by what decides its
    content: the requirements, constraints.txt, torch's pin, the host's Python
    and platform (the wheels are the host pip's choice for them)."""
    cache = Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache")
    key = hashlib.sha256(json.dumps({
        "requirements": _requirements(), "torch": TORCH,
        "constraints": (ROOT / "constraints.txt").read_text(),
        "python": list(sys.version_info[:2]), "platform": sysconfig.get_platform(),
    }, sort_keys=True).encode()).hexdigest()[:16]
    return cache / "telethermal" / f"wheelhouse-{key}"


def _fill_wheelhouse(wheels: Path) -> None:
    """Wheels for the image, by the host's pip: torch's CPU build first
    (refusing the CUDA build before any of its libraries is fetched), then
    everything else; the project itself is built inside the image."""
    pip = [sys.executable, "-m", "pip", "--disable-pip-version-check"]
    torch = _run(pip + ["download", "--no-deps", "--no-index", "-d", str(wheels), TORCH],
                 600, check=False)
    if torch.returncode != 0:        # no local wheel: whatever the configured indexes serve
        _run(pip + ["download", "--no-deps", "-d", str(wheels), TORCH], 600)
    _check_wheelhouse(wheels)
    _run(pip + ["wheel", "-q", "-w", str(wheels), "--find-links", str(wheels),
                "-c", str(ROOT / "constraints.txt"), *_requirements()], 900)
    _check_wheelhouse(wheels)


def _check_wheelhouse(wheels: Path) -> None:
    got = [p.name for p in wheels.glob("torch-*.whl")]
    assert got and all("+cpu" in name for name in got), \
        f"the host's pip gives {got}, not torch's CPU build: point it at one " \
        "(PIP_FIND_LINKS or PIP_EXTRA_INDEX_URL with torch's CPU index)"
    cuda = [p.name for p in wheels.glob("nvidia*.whl")]
    assert not cuda, f"CUDA wheels in the wheelhouse: {cuda}"


def _wheelhouse(timings) -> Path:
    """The filled wheelhouse: the cached one when complete, else filled now
    (into a temporary folder renamed when done, so a run cut short leaves
    nothing half-filled behind); older ones are removed."""
    house = _wheelhouse_dir()
    if not (house / ".complete").is_file():
        house.parent.mkdir(parents=True, exist_ok=True)
        with timings.stage("wheelhouse filled by the host's pip"):
            tmp = Path(tempfile.mkdtemp(prefix=".filling-", dir=house.parent))
            try:
                _fill_wheelhouse(tmp)
                (tmp / ".complete").write_text("filled by tests/integration/"
                                               "test_compose_up.py\n")
                shutil.rmtree(house, ignore_errors=True)
                tmp.rename(house)
            finally:
                shutil.rmtree(tmp, ignore_errors=True)
        for old in house.parent.glob("wheelhouse-*"):
            if old != house:
                shutil.rmtree(old, ignore_errors=True)
    _check_wheelhouse(house)
    return house


def _link_wheels(house: Path, ctx: Path) -> None:
    """The wheels into the build context: hard links where the cache and the
    context share a file system, else copies."""
    dest = ctx / "deploy" / "wheels"
    dest.mkdir(parents=True, exist_ok=True)
    for wheel in house.glob("*.whl"):
        try:
            os.link(wheel, dest / wheel.name)
        except OSError:
            shutil.copy2(wheel, dest / wheel.name)


def _package_files(package: Path) -> dict[str, str]:
    """sha256 of each file of the package (bytecode caches aside), by path."""
    return {str(p.relative_to(package)): hashlib.sha256(p.read_bytes()).hexdigest()
            for p in sorted(package.rglob("*"))
            if p.is_file() and "__pycache__" not in p.parts}


#: The demo profile's own command (docker-compose.yml's), on one material
#: with a 1.5 s contact (its default: three materials, 5 s each): what the
#: test checks of it (the user setting, the out folder's owner, exit codes,
#: demo.json, Matplotlib's config folder) is the same for any touch.
DEMO_COMMAND = [*yaml.safe_load((ROOT / "docker-compose.yml").read_text())["services"]["demo"]
                ["command"], "--materials", "wood", "--contact-s", "1.5"]

OVERRIDE = {
    "services": {
        # All traffic on the containers' own loopback: the slave has no
        # network but lo, the master joins it (docker-compose.yml).
        "slave": {"image": IMAGE, "network_mode": "none"},
        "master": {"image": IMAGE,
                   # a master that records, to read a recording cut by `down`
                   "command": ["master", "--config", "/rec/master.toml"],
                   "volumes": ["./rec:/rec"]},
        "view": {"image": IMAGE},
        "demo": {"image": IMAGE, "network_mode": "none", "command": DEMO_COMMAND},
    },
}


@pytest.fixture(scope="module")
def stack(engine, base_image, timings):
    """A copy of the project with the wheelhouse filled and the image built
    offline; yields a function running compose there. ``down`` at the end."""
    ctx = Path(tempfile.mkdtemp(prefix="telethermal-compose-"))
    ctx.chmod(0o755)
    house = _wheelhouse(timings)
    with timings.stage("build context: sources copied, wheels linked"):
        _copy_context(ctx)
        _link_wheels(house, ctx)
    with timings.stage("image built offline (--network none)"):
        _run(["docker", "build", "--network", "none", "--build-arg", f"BASE={base_image}",
              "-f", "deploy/Dockerfile", "-t", IMAGE, "."], 900, cwd=ctx)
    # (The build ran deploy/check-no-cuda.sh on the dependencies, or a cached
    # layer where it passed stands: a failed check fails the build, which _run
    # raises. test_image_is_small_and_has_no_cuda checks the image itself.)
    (ctx / "docker-compose.override.yml").write_text(yaml.safe_dump(OVERRIDE))
    rec = ctx / "rec"
    rec.mkdir(mode=0o777)
    rec.chmod(0o777)
    master_toml = (ctx / "deploy" / "compose" / "master.toml").read_text()
    (rec / "master.toml").write_text(master_toml.replace(
        "[master]\n", '[master]\nrecord_dir = "."\n', 1))

    def compose(*argv, timeout_s: float = 300, check: bool = True, env: dict | None = None):
        return _run([*engine, "-p", PROJECT, *argv], timeout_s, check=check, cwd=ctx,
                    env={**os.environ, **(env or {})})

    compose.ctx = ctx
    compose.argv = [*engine, "-p", PROJECT]
    try:
        yield compose
    finally:
        compose("--profile", "demo", "down", "--remove-orphans", "-t", "15", check=False)
        subprocess.run(["rm", "-rf", str(ctx)], check=False)


def _health(container: str) -> dict:
    r = _run(["docker", "inspect", "--format", "{{json .State}}", container], 20, check=False)
    return json.loads(r.stdout) if r.returncode == 0 else {}


def _named(pattern: str) -> str:
    """The id of the container (running or not) whose name matches, or ''."""
    r = _run(["docker", "ps", "-aq", "--filter", f"name={pattern}"], 20, check=False)
    return r.stdout.split()[0] if r.stdout.split() else ""


def _container(compose, service: str) -> str:
    return compose("ps", "-q", service).stdout.strip()


def _wait_health(container: str, want: str, timeout_s: float) -> float:
    t0 = time.monotonic()
    while time.monotonic() - t0 < timeout_s:
        if _health(container).get("Health", {}).get("Status") == want:
            return time.monotonic() - t0
        time.sleep(0.5)
    raise AssertionError(f"{container} not {want} in {timeout_s} s: {_health(container)}")


def test_image_is_small_and_has_no_cuda(stack):
    size = int(_run(["docker", "image", "inspect", "--format", "{{.Size}}", IMAGE], 20)
               .stdout)
    found = _run(["docker", "run", "--rm", "--network", "none", "--user", "0", "--entrypoint", "sh", IMAGE,
                  "-c", "find / -xdev \\( -iname 'libcudart*' -o -iname 'libcublas*' -o "
                  "-iname 'libcudnn*' -o -iname 'libnccl*' \\) -print"], 120).stdout
    assert found.strip() == ""
    torch = _run(["docker", "run", "--rm", "--network", "none", "--entrypoint", "python",
                  IMAGE, "-c", "import torch; print(torch.__version__, torch.version.cuda)"],
                 120).stdout.split()
    assert torch == ["2.13.0+cpu", "None"], torch
    assert size < 2.0e9, f"image {size / 1e9:.2f} GB"
    print(f"image {IMAGE}: {size / 1e9:.2f} GB")


def test_the_image_holds_this_checkouts_sources(stack):
    """Built from the sources under test, not a cached image of older ones:
    the installed package's files are this checkout's src/telethermal, byte
    for byte, every module included."""
    listing = ("import hashlib, json, pathlib, telethermal\n"
               "root = pathlib.Path(telethermal.__file__).parent\n"
               "print(json.dumps({str(p.relative_to(root)): "
               "hashlib.sha256(p.read_bytes()).hexdigest() for p in root.rglob('*') "
               "if p.is_file() and '__pycache__' not in p.parts}))\n")
    r = _run(["docker", "run", "--rm", "--network", "none", "--entrypoint", "python", IMAGE,
              "-c", listing], 120)
    installed = json.loads(r.stdout)
    sources = _package_files(ROOT / "src" / "telethermal")
    assert installed == {name: sources.get(name) for name in installed}, \
        sorted(name for name in installed if installed[name] != sources.get(name))
    modules = {name for name in sources if name.endswith(".py")}
    assert modules <= set(installed), sorted(modules - set(installed))


def test_up_waits_for_training_then_a_touch_through_exec(stack, timings):
    """``up`` starts the master only once the slave is healthy, and the
    slave's models train longer than the first probe: the probe fails
    first, in the start period, without a warning anywhere; a touch right
    after ``up`` waits for the session and comes back identified."""
    seen = []
    with timings.stage("up until both healthy"):
        up = subprocess.Popen([*stack.argv, "up", "-d", "--no-build"], cwd=stack.ctx,
                              stdin=subprocess.DEVNULL,
                              stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
        while up.poll() is None:
            slave = _named(f"{PROJECT}.slave")
            if slave:
                health = _health(slave).get("Health", {})
                seen.append((health.get("Status"), bool(_named(f"{PROJECT}.master")),
                             any(e.get("ExitCode") != 0 for e in health.get("Log") or [])))
            time.sleep(0.3)
        out, _ = up.communicate()
        assert up.returncode == 0, out
        _wait_health(_container(stack, "master"), "healthy", 60)
    # The master did not exist while the slave was still starting, and a
    # probe failed while the slave trained (the start period).
    assert any(status == "starting" and failed for status, _, failed in seen), seen
    assert not any(master for status, master, _ in seen if status == "starting"), seen
    with timings.stage("one touch through exec"):
        r = stack("exec", "-T", "master", "telethermal", "admin", "touch", "--contact-s", "2",
                  timeout_s=120)
    assert "identified wood" in r.stdout and "against direct contact with wood" in r.stdout, \
        r.stdout
    logs = stack("logs", "--no-color", "slave", "master").stdout
    assert " ERROR " not in logs, logs[-3000:]
    warnings = [line for line in logs.splitlines() if " WARNING " in line]
    if warnings:
        # Only what a stalled display loop causes, with the stall on record
        # (tests/realclock.py: a loaded machine's outcome, not the stack's).
        assert all(STALL_WARNING.search(line) for line in warnings), warnings
        report = json.loads(stack("exec", "-T", "master", "telethermal", "admin", "--json",
                                  "report", timeout_s=60).stdout)
        assert stalled(report["loop"]), (warnings, report["loop"])
    assert "touch over contact_id=1" in logs


def test_the_live_view_serves_its_page_in_the_namespace(stack, timings):
    """The view profile: its page on the namespace's port 8050, which the
    slave publishes to the host's loopback (here the slave has no network,
    so the page is fetched from inside, through exec)."""
    with timings.stage("view up"):
        stack("--profile", "view", "up", "-d", "--no-build", "view", timeout_s=120)
    fetch = ("import time, urllib.request\n"
             "for _ in range(60):\n"
             "    try:\n"
             "        page = urllib.request.urlopen('http://127.0.0.1:8050/', timeout=2)"
             ".read().decode()\n"
             "        break\n"
             "    except OSError:\n"
             "        time.sleep(0.5)\n"
             "print(len(page), 'telethermal' in page.lower())\n")
    r = stack("exec", "-T", "master", "python", "-c", fetch, timeout_s=60)
    assert r.stdout.split()[1] == "True", r.stdout
    logs = stack("logs", "--no-color", "view").stdout
    assert "view: http://127.0.0.1:8050/  (live: yes" in logs, logs
    stack("--profile", "view", "stop", "-t", "10", "view", timeout_s=60)
    stack("--profile", "view", "rm", "-f", "view", timeout_s=60)


def test_master_unhealthy_while_the_slave_is_away_then_healthy(stack, timings):
    """The slave frozen (``docker pause``: its process and sockets stay, it
    answers nothing): the master's healthcheck goes unhealthy; unpaused,
    healthy again with no restart of either."""
    slave, master = _container(stack, "slave"), _container(stack, "master")
    _run(["docker", "pause", slave], 30)
    try:
        away_s = _wait_health(master, "unhealthy", 90)
    finally:
        _run(["docker", "unpause", slave], 30)
    with timings.stage("master healthy again after the slave came back"):
        _wait_health(master, "healthy", 90)
    assert away_s > 0
    r = stack("exec", "-T", "master", "telethermal", "admin", "status", timeout_s=60)
    assert "master: idle, peer alive" in r.stdout, r.stdout


def test_down_mid_touch_leaves_the_pads_safe_and_the_recording_readable(stack, timings):
    stack("exec", "-T", "master", "telethermal", "admin", "touch", "--contact-s", "10",
          "--no-wait", timeout_s=60)
    time.sleep(2.0)
    with timings.stage("stop mid-touch (SIGTERM)"):
        stack("stop", "-t", "15", timeout_s=120)
    for service in ("slave", "master"):
        code = _health(_container(stack, service)).get("ExitCode")
        assert code == 0, f"{service} exited {code}"
    logs = stack("logs", "--no-color", "slave", "master").stdout
    assert "stopping: display pad to the safe state" in logs, logs[-3000:]
    assert "stopping: pad to safe state, sockets closed" in logs
    recordings = sorted((stack.ctx / "rec").glob("*.mcap"))
    assert recordings, list((stack.ctx / "rec").iterdir())
    rec = read_recording(recordings[-1])
    assert rec.role == "master" and sum(len(v) for v in rec.topics.values()) > 0
    with timings.stage("down"):
        stack("down", "-t", "15", timeout_s=120)
    assert _run(["docker", "ps", "-aq", "--filter", f"name={PROJECT}"], 20).stdout.strip() == ""


def test_demo_profile_with_the_out_folder_missing_then_owned(stack, timings):
    out = stack.ctx / "out"
    shutil.rmtree(out, ignore_errors=True)
    # Missing: the engine makes it as root; the container (uid 1000) says so.
    r = stack("--profile", "demo", "run", "--rm", "demo", check=False, timeout_s=120)
    text = " ".join((r.stdout + r.stderr).split())      # as rich wrapped it
    assert r.returncode == 2, text
    assert "Traceback" not in text and "uid 0 gid 0" in text and "TELETHERMAL_UID" in text
    # Owned by another user than the container's.
    os.chown(out, 4242, 4242)
    r = stack("--profile", "demo", "run", "--rm", "demo", check=False, timeout_s=120)
    assert r.returncode == 2 and "uid 4242" in " ".join((r.stdout + r.stderr).split())
    # The documented user setting: the container runs as the folder's owner.
    with timings.stage("demo profile"):
        r = stack("--profile", "demo", "run", "--rm", "demo", timeout_s=300,
                  env={"TELETHERMAL_UID": "4242", "TELETHERMAL_GID": "4242"})
    assert "services stopped: exit codes slave 0, master 0" in r.stdout, r.stdout[-3000:]
    assert (out / "demo" / "demo.json").is_file()
    assert "Matplotlib" not in r.stdout + r.stderr       # its config folder is writable
    assert (out / "demo" / "demo.json").stat().st_uid == 4242
    with timings.stage("down (demo)"):
        stack("--profile", "demo", "down", "-t", "15", timeout_s=120)
