"""Run one function in a forked child process while the parent goes on, and get its result.

Reading a long bag, and the Kalman filters and scores of ``calibrate``'s model choice, are CPU
work in Python and numpy that holds the GIL (chunk decompression too), so a second core helps
only from a second process. A fork starts at once (no imports, the open bag's state and the
records are copied) and sends back a small pickled result. Linux only; elsewhere, with one
core, with other threads running or in a daemonic worker, :func:`fork_available` is false and
the caller works serially.
"""

from __future__ import annotations

import os
import signal
import sys
import threading
import warnings
from collections.abc import Callable
from typing import Any

__all__ = ['ONE_PROCESS_VARIABLE', 'ForkedCall', 'fork_available']

#: the environment variable that keeps every command in one process when set to ``1`` (a batch
#: system that counts processes, a profiler)
ONE_PROCESS_VARIABLE = 'FOG_TEMP_COMP_PROCESSES'


def fork_available() -> bool:
    """Whether :class:`ForkedCall` may be used here.

    Linux, more than one CPU, no other Python thread (a fork copies only the calling
    thread; a lock another one held would stay locked in the child, e.g. in a Dask worker),
    not a daemonic ``multiprocessing`` worker (a ``Pool``'s: it may not have children), and
    not asked for one process (:data:`ONE_PROCESS_VARIABLE` set to ``1``).
    """
    cpus = len(os.sched_getaffinity(0)) if hasattr(os, 'sched_getaffinity') else os.cpu_count()
    return (
        os.environ.get(ONE_PROCESS_VARIABLE, '') != '1'
        and sys.platform.startswith('linux')
        and (cpus or 1) > 1
        and threading.active_count() == 1
        and not _daemonic()
    )


def _daemonic() -> bool:
    """Whether this process is a daemonic ``multiprocessing`` child (which imported it)."""
    multiprocessing = sys.modules.get('multiprocessing')
    return multiprocessing is not None and bool(multiprocessing.current_process().daemon)


class ForkedCall:
    """``function(*args)`` in a forked child; :meth:`result` waits for it.

    The child ignores SIGINT (Ctrl-C reaches the parent, which stops the child), and any
    exception in it becomes a ``None`` result: the caller then does the work itself. So does a
    child that cannot be started (out of processes or memory). Use as a context manager, or
    call :meth:`close`, so the child never outlives the call.
    """

    def __init__(self, function: Callable[..., Any], *args: Any) -> None:
        import multiprocessing  # here: ~10 ms, only for a bag worth splitting

        context = multiprocessing.get_context('fork')
        for stream in (sys.stdout, sys.stderr):  # else the child flushes the parent's buffer
            stream.flush()
        self._receive, send = context.Pipe(duplex=False)
        self._process = context.Process(
            target=_child, args=(function, args, send), daemon=True, name='fog-temp-comp-child'
        )
        try:
            with warnings.catch_warnings():
                # Python 3.12+ warns of a fork while native threads run (numpy's BLAS pool);
                # the child runs only this package's numpy code, and a warnings-as-errors
                # setting must not turn the fork into a child the parent does not know of
                warnings.simplefilter('ignore', DeprecationWarning)
                self._process.start()
            self._started = True
        except Exception:  # no child (out of processes, memory): result() is None, caller works
            self._started = False
        finally:
            send.close()

    def result(self) -> Any | None:
        """The function's return value, or None if it raised or the child died."""
        try:
            ok, value = self._receive.recv()
        except (EOFError, OSError):
            ok, value = False, None
        finally:
            self.close()
        return value if ok else None

    def close(self) -> None:
        """Stop the child if it still runs; release the pipe."""
        self._receive.close()
        if not self._started:
            return
        if self._process.is_alive():
            self._process.kill()
        self._process.join()

    def __enter__(self) -> ForkedCall:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def _child(function: Callable[..., Any], args: tuple[Any, ...], send: Any) -> None:
    """The child: the parent's signal handlers do not apply here; send (ok, value)."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    for name in ('SIGTERM', 'SIGHUP'):
        signal.signal(getattr(signal, name), signal.SIG_DFL)
    try:
        message: tuple[bool, Any] = (True, function(*args))
    except BaseException:  # the parent redoes the work and reports the error
        message = (False, None)
    try:
        send.send(message)
    except Exception:  # e.g. unpicklable: the parent sees EOF and redoes the work
        pass
    finally:
        send.close()
