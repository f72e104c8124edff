"""Ctrl-C ends any ``sphere-twin`` command with one line and exit status 130, even in the
middle of a compiled integration, where numba turns the KeyboardInterrupt into a SystemError
("CPUDispatcher(...) returned a result with an exception set") and Python printed both
tracebacks and exited with 1."""

import os
import signal
import subprocess
import sys
import threading
from pathlib import Path

import pytest

from sphere_twin.cli import INTERRUPTED_STATUS, interrupted

REPO = Path(__file__).resolve().parents[1]
EXAMPLE_BAG = REPO / 'bags' / 'example'
# What replay-check prints on stderr every few seconds while it integrates the recording.
PROGRESS_PREFIX = 'replay-check: replaying: '
# The start (imports, the kernel cache) and the first progress line (5 s in) take seconds;
# the whole replay more than a minute, so the signal lands inside it.
PROGRESS_TIMEOUT_S = 120.0
EXIT_TIMEOUT_S = 60.0


def _as_in_a_terminal() -> None:
    """The child's SIGINT as a terminal's foreground command has it. A suite started as a
    background job of a non-interactive shell inherits SIGINT ignored, and the command would
    replay to its end (status 0) instead of being interrupted."""
    signal.signal(signal.SIGINT, signal.SIG_DFL)


def _numba_style_error() -> SystemError:
    """What numba raises when a KeyboardInterrupt arrived while its machine code ran."""
    error = SystemError('CPUDispatcher(<function rhs>) returned a result with an exception set')
    error.__context__ = KeyboardInterrupt()
    return error


def test_an_interrupt_is_told_from_a_bug():
    assert interrupted(KeyboardInterrupt())
    assert interrupted(_numba_style_error())
    plain = SystemError('a bug of our own')
    assert not interrupted(plain)
    caused = ValueError('a bug')
    caused.__cause__ = RuntimeError('below')
    assert not interrupted(caused)
    assert INTERRUPTED_STATUS == 130


def _read_stderr(process: subprocess.Popen[str], lines: list[str],
                 started: threading.Event) -> threading.Thread:
    """Collect stderr's lines in ``lines`` on a thread; ``started`` is set at the first
    progress line (the replay is integrating), or at the end of stderr."""

    def read() -> None:
        assert process.stderr is not None
        for line in process.stderr:
            lines.append(line.rstrip('\n'))
            if line.startswith(PROGRESS_PREFIX):
                started.set()
        started.set()  # ended without one: let the test see why

    reader = threading.Thread(target=read, daemon=True)
    reader.start()
    return reader


@pytest.mark.slow
def test_ctrl_c_in_a_compiled_integration_is_one_line_and_status_130(tmp_path):
    env = {**os.environ, 'PYTHONPATH': os.pathsep.join(
        filter(None, (str(REPO), os.environ.get('PYTHONPATH'))))}
    process = subprocess.Popen(
        [sys.executable, '-m', 'sphere_twin.cli', 'replay-check', str(EXAMPLE_BAG)],
        cwd=tmp_path, env=env, stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE, text=True, preexec_fn=_as_in_a_terminal)
    lines: list[str] = []
    started = threading.Event()
    reader = _read_stderr(process, lines, started)
    try:
        assert started.wait(PROGRESS_TIMEOUT_S), lines
        assert process.poll() is None, lines  # still replaying
        process.send_signal(signal.SIGINT)
        status = process.wait(EXIT_TIMEOUT_S)
    finally:
        if process.poll() is None:
            process.kill()
            process.wait()
    reader.join(EXIT_TIMEOUT_S)  # the last lines, written as it ended
    text = '\n'.join(lines)
    assert status == INTERRUPTED_STATUS, text
    assert 'Traceback' not in text and 'SystemError' not in text, text
    said = [line for line in lines if not line.startswith(PROGRESS_PREFIX)]
    assert said == ['sphere-twin replay-check: interrupted'], text
