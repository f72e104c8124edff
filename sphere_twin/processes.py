"""Start and stop ROS 2 node processes: the one way the demo and the tests do it.

Every child gets ``ROS_DOMAIN_ID`` and, unless the caller's environment already chose a
range, ``ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST``, so by default DDS discovery stays on
this machine. Stopping signals the child's own PID (never a process name): SIGINT, then
SIGTERM, then SIGKILL, each after a timeout. On Linux a child also receives SIGTERM if the
process that started it dies, so an aborted test run leaves no node behind.

Output goes to anonymous temporary files rather than pipes, so a chatty child can never
block on a full pipe nobody is reading, and no reader threads are needed.

Nothing here imports rclpy: the supervisor runs nodes, it does not join their graph.

Examples
--------
>>> with running_nodes(NodeSpec('simulator'), NodeSpec('monitor')) as group:  # doctest: +SKIP
...     time.sleep(3.0)
>>> [p.returncode for p in group.processes]  # doctest: +SKIP
[0, 0]
"""

from __future__ import annotations

import contextlib
import ctypes
import dataclasses
import itertools
import os
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from collections.abc import Iterator, Mapping, Sequence
from pathlib import Path
from typing import IO

from sphere_twin.node_runtime.ros_env import DOMAIN_ID_VAR, ensure_localhost_discovery

# Fresh domains come from 1..101. Fast DDS derives UDP ports from the domain id and stays
# below the Linux ephemeral port range up to 101; 0 is everybody's default domain, so
# avoiding it keeps demos and tests apart from any other ROS graph on this machine.
MIN_DOMAIN_ID = 1
MAX_DOMAIN_ID = 101

DEFAULT_STOP_TIMEOUT_S = 10.0
POLL_PERIOD_S = 0.05
# Escalation order of stop(): the first is what a node treats as Ctrl-C.
STOP_SIGNALS = (signal.SIGINT, signal.SIGTERM, signal.SIGKILL)

_PR_SET_PDEATHSIG = 1  # from <linux/prctl.h>
_domain_counter = itertools.count()
# Domain ids this process handed out and still reserves (id -> open lock file), oldest first.
_held_domains: dict[int, IO[str]] = {}
DOMAINS_HELD = 32
DOMAIN_LOCK_DIR = 'sphere_twin_domains'


def fresh_domain_id() -> int:
    """A ROS domain id in [MIN_DOMAIN_ID, MAX_DOMAIN_ID] that no other process on this machine
    holds, and that this one has not handed out recently.

    Consecutive calls cycle through the range from an offset derived from the PID. Each id
    handed out is reserved by an exclusive lock on a file of its own in the temporary
    directory, held until this process has handed out DOMAINS_HELD more (or exits), so that
    concurrent runs (two test suites, a demo beside a test) never share a domain; an id
    another process holds is skipped. Without a free one it falls back to the next in turn.
    """
    span = MAX_DOMAIN_ID - MIN_DOMAIN_ID + 1
    for _ in range(span):
        domain_id = MIN_DOMAIN_ID + (os.getpid() + next(_domain_counter)) % span
        if _reserve(domain_id):
            return domain_id
    return domain_id


def _reserve(domain_id: int) -> bool:
    """Lock ``domain_id``'s file for this process; False if another process holds it."""
    import fcntl

    if domain_id in _held_domains:
        _held_domains.pop(domain_id).close()  # ours, handed out long ago: hand it out again
    directory = Path(tempfile.gettempdir()) / DOMAIN_LOCK_DIR
    directory.mkdir(exist_ok=True)
    handle = open(directory / f'{domain_id}.lock', 'w')  # noqa: SIM115 (held open: the lock)
    try:
        fcntl.flock(handle, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except OSError:
        handle.close()
        return False
    _held_domains[domain_id] = handle
    while len(_held_domains) > DOMAINS_HELD:
        _held_domains.pop(next(iter(_held_domains))).close()
    return True


def child_environment(domain_id: int, env_overrides: Mapping[str, str] | None = None,
                      base_env: Mapping[str, str] | None = None) -> dict[str, str]:
    """The environment a node process is started with.

    Parameters
    ----------
    domain_id : int
        Value of ``ROS_DOMAIN_ID``.
    env_overrides : Mapping of str to str, optional
        Variables to set on top of ``base_env``.
    base_env : Mapping of str to str, optional
        Starting point; ``os.environ`` by default.

    Returns
    -------
    dict of str to str
        ``base_env`` updated with ``env_overrides``, ``ROS_DOMAIN_ID`` set, and
        ``ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST`` unless either of them already set it.
    """
    env = dict(os.environ if base_env is None else base_env)
    env.update(env_overrides or {})
    ensure_localhost_discovery(env)
    env[DOMAIN_ID_VAR] = str(int(domain_id))
    # Python children write their output as it happens, so it can be watched while they run.
    env.setdefault('PYTHONUNBUFFERED', '1')
    return env


def resolve_executable(name: str) -> str:
    """Full path of a console script or program.

    Looked up next to the running Python interpreter (a virtual environment's ``bin/``),
    next to the running script (colcon installs a package's executables together in
    ``lib/<package>/``), then on ``PATH``. A name containing a path separator is returned as
    it is.

    Raises
    ------
    FileNotFoundError
        If the executable is found nowhere.
    """
    if os.sep in name:
        return name
    for directory in (Path(sys.executable).parent, Path(sys.argv[0]).resolve().parent):
        candidate = directory / name
        if candidate.is_file() and os.access(candidate, os.X_OK):
            return str(candidate)
    found = shutil.which(name)
    if found is None:
        raise FileNotFoundError(
            f'executable {name!r} not found next to {sys.executable} nor on PATH; '
            'run `make setup` (or `colcon build` and source the workspace)')
    return found


def _terminate_with_parent() -> None:
    """Ask the kernel to SIGTERM this (child) process when its parent dies (Linux only)."""
    libc = ctypes.CDLL(None, use_errno=True)
    libc.prctl(_PR_SET_PDEATHSIG, int(signal.SIGTERM))


@dataclasses.dataclass(eq=False)
class NodeProcess:
    """A started node process; returned by :func:`start_node`.

    Attributes
    ----------
    name : str
        The executable as the caller named it.
    command : tuple of str
        The full command line.
    domain_id : int
        Its ``ROS_DOMAIN_ID``.
    popen : subprocess.Popen
    """

    name: str
    command: tuple[str, ...]
    domain_id: int
    popen: subprocess.Popen[bytes]
    _stdout: IO[bytes] = dataclasses.field(repr=False)
    _stderr: IO[bytes] = dataclasses.field(repr=False)
    _final_output: tuple[str, str] | None = dataclasses.field(default=None, repr=False)

    @property
    def pid(self) -> int:
        """The process's own PID, the only thing it is ever signalled by."""
        return self.popen.pid

    @property
    def returncode(self) -> int | None:
        """Exit code, or None while running (negative: killed by that signal)."""
        return self.popen.poll()

    def running(self) -> bool:
        """Whether the process has not exited yet."""
        return self.popen.poll() is None

    def stdout_text(self) -> str:
        """Everything the process wrote to standard output so far."""
        if self._final_output is not None:
            return self._final_output[0]
        return _read_all(self._stdout)

    def stderr_text(self) -> str:
        """Everything the process wrote to standard error so far (ROS logging goes here)."""
        if self._final_output is not None:
            return self._final_output[1]
        return _read_all(self._stderr)

    def _release_output(self) -> None:
        """Keep the output of the exited process in memory and close its files."""
        if self._final_output is None:
            self._final_output = (_read_all(self._stdout), _read_all(self._stderr))
            self._stdout.close()
            self._stderr.close()

    def send_signal(self, signum: int) -> None:
        """Signal this process's own PID; does nothing once it has exited."""
        self.popen.send_signal(signum)

    def wait(self, timeout_s: float | None) -> int:
        """Wait for the exit code; raises ``subprocess.TimeoutExpired`` after ``timeout_s``."""
        return self.popen.wait(timeout_s)

    def wait_for_output(self, text: str, timeout_s: float) -> None:
        """Wait until ``text`` appears in the process's stdout or stderr.

        Raises
        ------
        RuntimeError
            If the process exits first.
        TimeoutError
            If ``text`` has not appeared within ``timeout_s``.
        """
        deadline = time.monotonic() + timeout_s
        while True:
            if text in self.stdout_text() or text in self.stderr_text():
                return
            if not self.running():
                raise RuntimeError(
                    f'{self.name} exited with {self.returncode} before printing {text!r}:\n'
                    f'{self.stderr_text()}')
            if time.monotonic() > deadline:
                raise TimeoutError(f'{self.name} did not print {text!r} within {timeout_s} s')
            time.sleep(POLL_PERIOD_S)


def _read_all(file: IO[bytes]) -> str:
    # pread leaves the file offset alone; the child shares that offset and keeps writing.
    fd = file.fileno()
    return os.pread(fd, os.fstat(fd).st_size, 0).decode(errors='replace')


def start_node(executable: str, args: Sequence[str] = (),
               env_overrides: Mapping[str, str] | None = None,
               domain_id: int | None = None) -> NodeProcess:
    """Start a node executable as a child process.

    Parameters
    ----------
    executable : str
        Console script name (``simulator``, ``monitor``; see :func:`resolve_executable`) or a
        path.
    args : sequence of str
        Command-line arguments, e.g. from :func:`parameter_args`.
    env_overrides : Mapping of str to str, optional
        Environment variables to set for the child.
    domain_id : int, optional
        ``ROS_DOMAIN_ID``; :func:`fresh_domain_id` if omitted.

    Returns
    -------
    NodeProcess
    """
    if domain_id is None:
        domain_id = fresh_domain_id()
    command = (resolve_executable(executable), *args)
    # The files outlive this call: the handle reads them and stop() closes them.
    stdout = tempfile.TemporaryFile(prefix='sphere_twin_out_')  # noqa: SIM115
    stderr = tempfile.TemporaryFile(prefix='sphere_twin_err_')  # noqa: SIM115
    popen = subprocess.Popen(
        command,
        env=child_environment(domain_id, env_overrides),
        stdin=subprocess.DEVNULL,
        stdout=stdout,
        stderr=stderr,
        preexec_fn=_terminate_with_parent if sys.platform == 'linux' else None,
    )
    return NodeProcess(executable, command, domain_id, popen, stdout, stderr)


def stop(process: NodeProcess, timeout_s: float = DEFAULT_STOP_TIMEOUT_S) -> int:
    """Stop a node process and return its exit code.

    Sends SIGINT to the process's own PID and waits up to ``timeout_s``; if it is still
    running, SIGTERM and another ``timeout_s``; then SIGKILL. A process that already exited
    is only reaped.

    A node exits with 0 on SIGINT or SIGTERM once its ``main`` has installed its handlers;
    a signal in the first fraction of a second, while the interpreter is still importing,
    ends it with a non-zero code instead. Callers that need a clean exit wait for the node's
    start-up line first (:meth:`NodeProcess.wait_for_output`).

    Every process from :func:`start_node` must be stopped this way (directly or through a
    :class:`NodeGroup`), also one that exited by itself: this reaps it and closes its output
    files, whose text stays readable on the handle.

    Returns
    -------
    int
        The exit code (0 for a clean shutdown; negative: killed by that signal).
    """
    for signum in STOP_SIGNALS:
        if not process.running():
            break
        process.send_signal(signum)
        try:
            process.wait(None if signum == signal.SIGKILL else timeout_s)
        except subprocess.TimeoutExpired:
            continue
    returncode = process.popen.wait()
    process._release_output()
    return returncode


def parameter_args(**parameters: object) -> list[str]:
    """ROS command-line arguments setting node parameters.

    >>> parameter_args(max_messages=20, publish_rate_hz=100.0)
    ['--ros-args', '-p', 'max_messages:=20', '-p', 'publish_rate_hz:=100.0']
    """
    if not parameters:
        return []
    args = ['--ros-args']
    for name, value in parameters.items():
        args += ['-p', f'{name}:={value}']
    return args


@dataclasses.dataclass(frozen=True)
class NodeSpec:
    """What to start: an executable and its arguments."""

    executable: str
    args: tuple[str, ...] = ()


class NodeGroup:
    """Node processes sharing one ROS domain, stopped together.

    Parameters
    ----------
    domain_id : int, optional
        ``ROS_DOMAIN_ID`` of every process; :func:`fresh_domain_id` if omitted.
    env_overrides : Mapping of str to str, optional
        Environment variables set for every process.

    Attributes
    ----------
    processes : list of NodeProcess
        In start order.
    """

    def __init__(self, domain_id: int | None = None,
                 env_overrides: Mapping[str, str] | None = None) -> None:
        self.domain_id = fresh_domain_id() if domain_id is None else domain_id
        self.env_overrides = dict(env_overrides or {})
        self.processes: list[NodeProcess] = []

    def start(self, executable: str, args: Sequence[str] = (),
              env_overrides: Mapping[str, str] | None = None) -> NodeProcess:
        """Start one more node in the group's domain; see :func:`start_node`."""
        process = start_node(executable, args, {**self.env_overrides, **(env_overrides or {})},
                             self.domain_id)
        self.processes.append(process)
        return process

    def stop_all(self, timeout_s: float = DEFAULT_STOP_TIMEOUT_S) -> None:
        """Stop every process, the last started first; their exit codes stay on them.

        Reverse order lets consumers, started after their producers, stop first and so see
        everything the producers sent.
        """
        for process in reversed(self.processes):
            stop(process, timeout_s)


@contextlib.contextmanager
def running_nodes(*specs: NodeSpec, domain_id: int | None = None,
                  env_overrides: Mapping[str, str] | None = None,
                  stop_timeout_s: float = DEFAULT_STOP_TIMEOUT_S) -> Iterator[NodeGroup]:
    """Start nodes in a fresh domain for the duration of a ``with`` block.

    Parameters
    ----------
    *specs : NodeSpec
        Nodes to start, in order; more can be added with ``group.start``.
    domain_id, env_overrides
        See :class:`NodeGroup`.
    stop_timeout_s : float
        Per-signal timeout of :func:`stop` at exit.

    Yields
    ------
    NodeGroup
        Every process in it is stopped when the block exits, however it exits.
    """
    group = NodeGroup(domain_id, env_overrides)
    try:
        for spec in specs:
            group.start(spec.executable, spec.args)
        yield group
    finally:
        group.stop_all(stop_timeout_s)
