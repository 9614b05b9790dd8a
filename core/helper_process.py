"""A child Python process that takes part of a sub-step's work to another core.

A bake runs its simulation on one thread; numpy holds Python's lock between its calls, and a
spring mesh's self-collision detection is hundreds of calls on a few thousand elements each,
too short for two threads to overlap (measured: 8 % of a detection). A child process has a
lock of its own: the bake hands it a request (pickled, through a pipe), does its own share of
the work meanwhile, and reads the child's answer when it needs it.

The child is the interpreter Blender runs Python with (``sys.executable``, isolated as Blender
runs it) running this file; it loads this ``core`` package by path under a name of its own (``physanim_core``: core never
imports Blender or anything outside itself), calls ``module:function(setup)`` for the
handler of its requests, answers ``ready``, then answers each request with
``handler(request)``. It ends when the bake closes its input, or the bake's process ends.

Messages are pickles between this package's own processes, each framed by its length.
"""
from __future__ import annotations

import contextlib
import os
import pickle
import select
import signal
import struct
import subprocess
import sys
import threading
import weakref
from pathlib import Path

#: Seconds the child may take to start and answer ``ready`` before it is given up.
START_TIMEOUT = 30.0
#: Seconds the bake waits for an answer (for each part of it) before it takes the child for
#: stuck — stopped, or waiting on something that will not come —, ends it and does the work
#: itself: an answer takes milliseconds, its share of the bake's own work. (On Windows, whose
#: pipes cannot be waited on with a time limit, a timer ends the child at the limit instead,
#: which ends the wait.)
ANSWER_TIMEOUT = 60.0
#: Whether a pipe can be waited on with a time limit (``select``): not on Windows.
_SELECT = os.name == "posix"
#: Helpers alive at once at most (:func:`room`): each holds numpy and its task's data (about
#: 40 MB), and a bake steps its meshes one after another, so more than the free cores gain
#: nothing.
MAX_HELPERS = 4
_LIVE: weakref.WeakSet = weakref.WeakSet()
_LENGTH = struct.Struct("<Q")
_CORE = Path(__file__).resolve().parent
_PACKAGE = "physanim_core"


class HelperError(RuntimeError):
    """The child cannot answer: it did not start, exited, or failed (its reason)."""


def can_start() -> bool:
    """Whether ``sys.executable`` is a Python interpreter (a Blender build that names its own
    binary there would open Blender instead)."""
    name = os.path.basename(sys.executable or "").lower()
    return name.startswith("python") and os.path.isfile(sys.executable)


def pipes_safe() -> bool:
    """Whether writing to a child that has ended raises an error here rather than ending this
    process: SIGPIPE ignored, as Python sets it at start-up (an embedding program that leaves
    it at its default — some Blender builds did — is ended by such a write). Where it is at
    its default and this is the main thread, it is set to be ignored, as Python would have;
    elsewhere no helper starts."""
    if not hasattr(signal, "SIGPIPE"):
        return True  # (Windows: a broken pipe is always an error)
    if signal.getsignal(signal.SIGPIPE) != signal.SIG_DFL:
        return True
    try:
        signal.signal(signal.SIGPIPE, signal.SIG_IGN)
    except ValueError:  # (not the main thread)
        return False
    return True


def cores() -> int:
    """The cores this process may run on (its CPU affinity, as a farm's job slot sets it)."""
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # (not on Linux)
        return os.cpu_count() or 1


def _environment() -> dict[str, str]:
    """The child's environment: this one, with its BLAS on one thread (unless set already):
    the child runs beside the bake on the core the bake leaves, and a BLAS thread pool would
    take the bake's core too (see ``addon/blas.py``)."""
    env = dict(os.environ)
    for name in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
        env.setdefault(name, "1")
    return env


def room() -> bool:
    """Whether another helper may start: fewer alive than the cores this process may run on
    less one (the bake's own), and than MAX_HELPERS."""
    return sum(h.alive for h in list(_LIVE)) < min(MAX_HELPERS, cores() - 1)


def _write(stream, message) -> None:
    data = pickle.dumps(message, protocol=pickle.HIGHEST_PROTOCOL)
    stream.write(_LENGTH.pack(len(data)))
    stream.write(data)
    stream.flush()


def _read_fd(fd: int, timeout: float | None, stop=None):
    """The next message from the pipe ``fd`` (read directly: nothing is buffered ahead, so
    waiting on the pipe is waiting for the message); EOFError when the pipe ended,
    TimeoutError when no part of it came within ``timeout`` seconds (None: no limit).
    ``stop()`` ends the writer: where a pipe cannot be waited on with a limit (Windows), a
    timer calls it at the limit, which ends the read (the pipe closes)."""
    size, = _LENGTH.unpack(_read_bytes(fd, _LENGTH.size, timeout, stop))
    return pickle.loads(_read_bytes(fd, size, timeout, stop))


def _read_bytes(fd: int, size: int, timeout: float | None, stop=None) -> bytes:
    parts, got = [], 0
    while got < size:
        timer, fired = None, []
        if timeout is not None and _SELECT:
            if not select.select([fd], [], [], timeout)[0]:
                raise TimeoutError
        elif timeout is not None and stop is not None:
            timer = threading.Timer(timeout, _expire, (fired, stop))
            timer.daemon = True
            timer.start()
        try:
            chunk = os.read(fd, min(size - got, 1 << 20))
        finally:
            if timer is not None:
                timer.cancel()
        if fired and not chunk:
            raise TimeoutError  # (the timer ended the writer: the pipe closed)
        if not chunk:
            raise EOFError
        parts.append(chunk)
        got += len(chunk)
    return b"".join(parts)


def _expire(fired: list, stop) -> None:
    """(A timer) the read waited its limit: say so, and end the writer."""
    fired.append(True)
    stop()


class Helper:
    """The child, seen from the bake. It starts at once and gets ready (about 0.3 s: numpy and
    the handler's modules) while the bake goes on: :attr:`ready` says whether it is, without
    waiting. :meth:`ask` sends a request, :meth:`answer` reads its answer (an answer to a
    request whose reader gave up, as when the bake was interrupted between the two, is read
    and dropped by the next :meth:`ask`). Any failure — the child would not start, exited,
    broke its pipe, gave no answer for ANSWER_TIMEOUT seconds — raises :class:`HelperError`,
    after which the helper is closed and the caller does the work itself. Ended by
    :meth:`close`, or when garbage-collected.

    Args:
        task: ``"module:function"``, a module of this package (dotted, from ``core``) and the
            function the child calls with ``setup`` for the handler of its requests.
        setup: what the handler is made from (picklable: numpy arrays, numbers, strings).
    """

    def __init__(self, task: str, setup):
        self._started = threading.Event()  # the child's first answer came (or its end)
        self._first = None
        self._ready = False
        self._asked = self._answered = 0  # requests sent, and the last one answered
        # -I: isolated, as Blender's own Python (no PYTHON* variables, no user site), so the
        # child imports the numpy the bake runs; its own session, so Ctrl+C in a terminal
        # reaches the bake (which ends the child), not the child
        self._proc = subprocess.Popen(
            [sys.executable, "-I", str(Path(__file__).resolve()), str(_CORE), task],
            stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.DEVNULL,
            env=_environment(), creationflags=getattr(subprocess, "CREATE_NO_WINDOW", 0),
            start_new_session=os.name == "posix")
        self._end = weakref.finalize(self, _end, self._proc)
        _LIVE.add(self)
        threading.Thread(target=self._wait_start, args=(setup,), name="physanim-helper",
                         daemon=True).start()

    def _wait_start(self, setup) -> None:
        """(A thread) the setup sent (larger than a pipe holds: written while the child
        starts, not by the bake), then the child's first answer, ``("ready", numpy's
        version)``; later answers are read by :meth:`answer` itself (a thread handing them
        over waited for Python's lock while the bake computed: a millisecond a request)."""
        try:
            _write(self._proc.stdin, setup)
            self._first = _read_fd(self._proc.stdout.fileno(), None)
        except Exception:  # (EOFError, a broken pipe, a garbled answer: the child exited)
            self._first = None
        self._started.set()

    @property
    def ready(self) -> bool:
        """Whether the child has answered ``ready`` (never waits). Raises HelperError when it
        ended instead."""
        if not self._ready:
            if not self._started.is_set():
                return False
            self._check_ready()
        return True

    def wait_ready(self, timeout: float = START_TIMEOUT) -> None:
        """Wait until the child is ready (for tests and benchmarks); HelperError if it ends."""
        if not self._ready:
            self._started.wait(timeout)
            self._check_ready()

    def _check_ready(self) -> None:
        import numpy

        if self._first != ("ready", numpy.__version__):
            self.close()
            reason = "it exited" if self._first is None else f"it answered {self._first!r} " \
                f"(numpy {numpy.__version__} here)"
            raise HelperError(f"the helper process did not start: {reason}")
        self._ready = True

    def ask(self, request) -> None:
        """Send ``request`` (the child must be :attr:`ready`). An answer left unread (its
        reader raised before reading it) is read first: a child writing a large answer into a
        full pipe would otherwise wait for the bake, while the bake writing a large request
        into the child's full pipe waited for the child."""
        if self._answered < self._asked:
            self.answer()
        self._asked += 1
        try:
            _write(self._proc.stdin, (self._asked, request))
        except (OSError, ValueError) as exc:  # (ValueError: a closed pipe)
            self.close()
            raise HelperError(f"the helper process exited: {exc}") from exc

    def answer(self):
        """The child's answer to the last request :meth:`ask` sent. A child that gives no part
        of it for ANSWER_TIMEOUT seconds is ended (HelperError), as one that exited."""
        while True:
            try:
                number, value = _read_fd(self._proc.stdout.fileno(), ANSWER_TIMEOUT,
                                         self._proc.kill)
            except TimeoutError as exc:
                self.close()
                raise HelperError("the helper process gave no answer within "
                                  f"{ANSWER_TIMEOUT:g} s: ended") from exc
            except Exception as exc:  # (EOFError, a broken pipe, a garbled answer)
                self.close()
                raise HelperError("the helper process exited") from exc
            self._answered = number
            if number == self._asked:
                return value

    @property
    def alive(self) -> bool:
        """Not closed (the child may have ended on its own: the next answer says so)."""
        return self._end.alive

    def close(self) -> None:
        """End the child (its input closed; killed if it does not end within a few seconds)."""
        self._end()


def _end(proc: subprocess.Popen) -> None:
    with contextlib.suppress(OSError, ValueError):
        proc.stdin.close()
    try:
        proc.wait(timeout=1)  # (it holds nothing to save: one blocked writing is killed)
    except subprocess.TimeoutExpired:
        proc.kill()
        proc.wait()
    with contextlib.suppress(OSError, ValueError):
        proc.stdout.close()


def _serve(core: str, task: str) -> int:
    """The child: the setup, then ``ready``, then an answer per request until the input ends.
    An exception in the handler ends the child (the bake does that work itself)."""
    import importlib
    import importlib.util

    spec = importlib.util.spec_from_file_location(
        _PACKAGE, Path(core) / "__init__.py", submodule_search_locations=[core])
    package = importlib.util.module_from_spec(spec)
    sys.modules[_PACKAGE] = package
    spec.loader.exec_module(package)
    module, function = task.split(":")
    # the answers on a copy of the output; the output itself (fd 1, where anything printed,
    # by Python or by a library, would go) joins stderr
    stdin, stdout = sys.stdin.fileno(), os.fdopen(os.dup(1), "wb")
    os.dup2(2, 1)
    try:
        setup = _read_fd(stdin, None)
        handler = getattr(importlib.import_module(f"{_PACKAGE}.{module}"), function)(setup)
    except EOFError:
        return 0
    import numpy

    _write(stdout, ("ready", numpy.__version__))
    while True:
        try:
            number, request = _read_fd(stdin, None)
        except EOFError:
            return 0
        _write(stdout, (number, handler(request)))


if __name__ == "__main__":
    sys.exit(_serve(sys.argv[1], sys.argv[2]))
