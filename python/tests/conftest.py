"""Shared fixtures of the probeless Python tests (run by ctest as python_test, or
``build/bin/probeless-python -m pytest python/tests``)."""

import itertools
import os
import pathlib
import signal
import subprocess
import sys
import time

import pytest

# A bus domain of this run only (ctest sets its own), before anything touches the bus.
os.environ.setdefault("PROBELESS_DOMAIN", f"pytest{os.getpid()}")

import probeless  # noqa: E402

SOURCE_DIR = pathlib.Path(
    os.environ.get("PROBELESS_SOURCE_DIR", pathlib.Path(__file__).resolve().parents[2]))
BUILD_DIR = pathlib.Path(
    os.environ.get("PROBELESS_BUILD_DIR",
                   pathlib.Path(probeless.__file__).resolve().parents[2]))
BIN_DIR = BUILD_DIR / "bin"
PYTHON = str(BIN_DIR / "probeless-python")
TESTS_DIR = pathlib.Path(__file__).resolve().parent

_topic_counter = itertools.count()


@pytest.fixture
def topic():
    """A fresh absolute topic name per use."""
    return f"/pytest/t{next(_topic_counter)}"


def shm_segments(pid=None):
    """Names in /dev/shm of this user's domain (those of participant `pid` only, if given)."""
    prefix = f"probeless.{os.getuid()}.{probeless.current_domain()}."
    names = [n for n in os.listdir("/dev/shm") if n.startswith(prefix)]
    if pid is not None:
        names = [n for n in names if f".p.{pid}." in n]
    return names


def wait_until(predicate, timeout=10.0, period=0.02):
    """Polls `predicate` until true; returns its last value."""
    deadline = time.monotonic() + timeout
    while True:
        value = predicate()
        if value or time.monotonic() > deadline:
            return value
        time.sleep(period)


def subscribers_of(topic_name, node_name=None):
    """Live subscribers of `topic_name` (of node `node_name`, if given) on the bus."""
    for t in probeless.list_topics():
        if t["topic"] == topic_name:
            return [s for s in t["subscribers"] if s["alive"]
                    and (node_name is None or s["node_name"] == node_name)]
    return []


class Process:
    """A child process with its output collected; stopped with SIGINT on close()."""

    def __init__(self, args, **kwargs):
        self.popen = subprocess.Popen(args, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                                      text=True, start_new_session=True, **kwargs)
        self.stdout = ""
        self.stderr = ""

    @property
    def pid(self):
        return self.popen.pid

    def stop(self, sig=signal.SIGINT, timeout=20.0):
        """Signals the process, waits for it and returns its exit code."""
        if self.popen.poll() is None:
            self.popen.send_signal(sig)
        return self.wait(timeout)

    def wait(self, timeout=20.0):
        out, err = self.popen.communicate(timeout=timeout)
        self.stdout += out
        self.stderr += err
        return self.popen.returncode

    def close(self):
        if self.popen.poll() is None:
            self.popen.kill()
            self.wait()


@pytest.fixture
def processes():
    """Starts Process objects; kills what is still running at the end of the test."""
    started = []

    def start(args, **kwargs):
        process = Process([str(a) for a in args], **kwargs)
        started.append(process)
        return process

    yield start
    for process in started:
        process.close()


def python_script(path, *args):
    """The command running a Python script with the package (what launch files exec)."""
    return [PYTHON, str(path), *args]


sys.path.insert(0, str(TESTS_DIR))
