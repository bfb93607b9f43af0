"""Child processes of the demo: isolated DDS environment, logs, orderly shutdown.

Every node of the demo runs as its own Python process (``python -m MODULE --ros-args …``) with
stdout and stderr in ``logs/NAME.log``. DDS isolation (docs: test/conftest.py uses the same rule):
``ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST`` and a ``ROS_DOMAIN_ID`` in 1..100 derived from the
demo's PID unless the user already set one, so two demos, a test run and a developer's stack on
the same machine do not see each other's topics.

Shutdown: ``stop`` sends SIGINT (rclpy shuts its context down and the node cleans up: the
recorder finishes its bag), then SIGTERM, then SIGKILL, each after a timeout.
"""
from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
import signal
import subprocess
import sys
import time

MAX_DOMAIN_ID = 100  # highest ROS_DOMAIN_ID used; every RMW maps 1..100 to valid UDP ports
LOG_TAIL_LINES = 20  # lines of a failed process's log shown to the user


def domain_id_from_pid(pid: int) -> int:
    """ROS_DOMAIN_ID in 1..100 from a process id (never 0, the shared default domain)."""
    return 1 + pid % MAX_DOMAIN_ID


def isolated_environment(base: Mapping[str, str], pid: int) -> dict[str, str]:
    """Child environment: localhost-only discovery and a private domain unless one is set."""
    env = dict(base)
    env['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'
    if not env.get('ROS_DOMAIN_ID', '').strip():
        env['ROS_DOMAIN_ID'] = str(domain_id_from_pid(pid))
    env['PYTHONUNBUFFERED'] = '1'
    env.setdefault('RCUTILS_LOGGING_BUFFERED_STREAM', '1')
    env.setdefault('OMP_NUM_THREADS', '1')  # 2 shared cores: no thread oversubscription
    return env


@dataclass
class NodeProcess:
    """One running node: its name, process and log file."""

    name: str
    process: subprocess.Popen[bytes]
    log_path: Path

    def running(self) -> bool:
        """Whether the process has not exited yet."""
        return self.process.poll() is None

    def returncode(self) -> int | None:
        """Exit code, or None while running."""
        return self.process.poll()


def start(name: str, module: str, args: Sequence[str], env: Mapping[str, str], log_dir: Path,
          cwd: Path | None = None) -> NodeProcess:
    """Start ``python -m module args`` with stdout+stderr in ``log_dir/name.log``."""
    log_dir.mkdir(parents=True, exist_ok=True)
    log_path = log_dir / f'{name}.log'
    with open(log_path, 'wb') as stream:
        process = subprocess.Popen([sys.executable, '-m', module, *args], env=dict(env),
                                   cwd=None if cwd is None else str(cwd), stdout=stream,
                                   stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL)
    return NodeProcess(name, process, log_path)


def stop(node: NodeProcess, timeout: float = 10.0) -> int:
    """SIGINT, then SIGTERM, then SIGKILL, waiting ``timeout`` s [wall] after each; exit code."""
    for sig in (signal.SIGINT, signal.SIGTERM):
        if not node.running():
            break
        node.process.send_signal(sig)
        try:
            node.process.wait(timeout=timeout)
        except subprocess.TimeoutExpired:
            continue
    if node.running():
        node.process.kill()
        node.process.wait(timeout=timeout)
    code = node.process.returncode
    return int(code) if code is not None else -1


def log_tail(path: Path, lines: int = LOG_TAIL_LINES) -> str:
    """The last ``lines`` lines of a log file ('' when it does not exist)."""
    try:
        text = path.read_text(encoding='utf-8', errors='replace')
    except FileNotFoundError:
        return ''
    return '\n'.join(text.rstrip().splitlines()[-lines:])


def first_dead(nodes: Sequence[NodeProcess]) -> NodeProcess | None:
    """The first node that has exited, or None when all still run."""
    for node in nodes:
        if not node.running():
            return node
    return None


def wait_exit(node: NodeProcess, others: Sequence[NodeProcess], timeout: float,
              poll: float = 0.1) -> NodeProcess | None:
    """Wait until ``node`` exits; returns another node if that one died first (or None).

    Raises TimeoutError when ``node`` is still running after ``timeout`` wall seconds.
    """
    deadline = time.monotonic() + timeout
    while node.running():
        dead = first_dead(others)
        if dead is not None:
            return dead
        if time.monotonic() > deadline:
            raise TimeoutError(f'{node.name} still running after {timeout:.0f} s')
        time.sleep(poll)
    return None


def describe_failure(node: NodeProcess) -> str:
    """A message naming the process, its exit code and the tail of its log."""
    return (f'{node.name} exited early with code {node.returncode()} (log {node.log_path}); '
            f'last lines:\n{log_tail(node.log_path)}')


__all__ = ['NodeProcess', 'describe_failure', 'domain_id_from_pid', 'first_dead',
           'isolated_environment', 'log_tail', 'start', 'stop', 'wait_exit']
