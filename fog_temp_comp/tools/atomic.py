"""Outputs that cannot lie: write beside the target, rename into place only when complete.

A command opens :class:`AtomicOutputs` around its whole run and asks it for a temporary path
per output (a file, a bag directory or a report directory). Each temporary path lies in a
hidden directory ``.<name>.partial-<pid>`` beside its target, so the rename stays on one file
system and a bag written there keeps its own name inside (``OUT/OUT.mcap``). On success every
output is renamed into place; on an error, Ctrl-C (SIGINT) or SIGTERM the partial outputs are
removed, one line on stderr says that nothing was written, and the exception goes on (the CLI
turns it into a non-zero exit code: 1, 130, 143).
"""

from __future__ import annotations

import errno
import os
import shutil
import signal
import sys
import threading
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from types import FrameType, TracebackType
from typing import Any, TextIO

__all__ = [
    'AtomicOutputs',
    'Terminated',
    'check_output_directory',
    'partial_dir',
    'terminating_on_signals',
]


class Terminated(BaseException):
    """Raised in the main thread on SIGTERM or SIGHUP inside an :class:`AtomicOutputs`."""

    def __init__(self, signum: int) -> None:
        super().__init__(f'terminated by {signal.Signals(signum).name}')
        self.signum = signum

    @property
    def exit_code(self) -> int:
        """The shell's code for death by this signal (128 + number)."""
        return 128 + self.signum


@contextmanager
def terminating_on_signals() -> Iterator[None]:
    """Inside, SIGTERM and SIGHUP raise :class:`Terminated` in the main thread.

    An interrupt raised where Python cannot propagate it (a ``__del__``, a weakref callback)
    prints no traceback: :class:`AtomicOutputs` still refuses to commit after it.
    """
    old = {}
    if threading.current_thread() is threading.main_thread():
        for signum in AtomicOutputs._SIGNALS:
            old[signum] = signal.signal(signum, AtomicOutputs._terminate)
    hook = sys.unraisablehook

    def quiet(unraisable: Any) -> None:
        if not isinstance(unraisable.exc_value, (KeyboardInterrupt, Terminated)):
            hook(unraisable)

    sys.unraisablehook = quiet
    try:
        yield
    finally:
        sys.unraisablehook = hook
        for signum, handler in old.items():
            signal.signal(signum, handler)


def partial_dir(target: Path) -> Path:
    """The hidden directory beside ``target`` that holds its output while it is written."""
    return target.parent / f'.{target.name}.partial-{os.getpid()}'


def check_output_directory(target: Path) -> None:
    """Raise FileNotFoundError naming ``target`` if its directory does not exist."""
    if not target.parent.is_dir():
        missing = 'is not a directory' if target.parent.exists() else 'does not exist'
        raise FileNotFoundError(errno.ENOENT, f'directory {target.parent} {missing}', str(target))


def _remove(path: Path) -> None:
    if path.is_dir() and not path.is_symlink():
        shutil.rmtree(path, ignore_errors=True)
    elif path.exists() or path.is_symlink():
        path.unlink(missing_ok=True)


class AtomicOutputs:
    """Group of outputs written under temporary names and renamed together at the end.

    Parameters
    ----------
    *announce : Path or None
        Outputs the command will write, named on stderr if it stops before it asked for them.
    stderr : text stream, optional
        Where to say that nothing was written (default ``sys.stderr``).

    Examples
    --------
    >>> with AtomicOutputs() as outputs:                    # doctest: +SKIP
    ...     save(coeffs, outputs.path(Path('coeffs.yaml')))

    """

    _SIGNALS = tuple(s for s in (signal.SIGTERM, getattr(signal, 'SIGHUP', None)) if s)

    def __init__(self, *announce: Path | None, stderr: TextIO | None = None) -> None:
        self._announce = [Path(a) for a in announce if a is not None]
        self._stderr = stderr
        # (target, temporary, mode): mode '' (new), 'merge' (into a directory), 'replace'
        self._targets: list[tuple[Path, Path, str]] = []
        self._old: dict[int, Any] = {}

    def path(
        self, target: str | Path, *, merge_into_dir: bool = False, replace: bool = False
    ) -> Path:
        """Temporary path to write ``target``'s content to.

        ``merge_into_dir``: ``target`` is a directory that may exist already (a report); its
        files are replaced one by one at the end, other files in it are left alone.
        ``replace``: ``target`` is a file that may exist and is replaced. Otherwise ``target``
        must not exist (checked now and again when the outputs are committed).
        """
        target = Path(target)
        if not (merge_into_dir or replace) and (target.exists() or target.is_symlink()):
            raise FileExistsError(f'{target}: exists already, not overwriting')
        if merge_into_dir and target.exists() and not target.is_dir():
            raise FileExistsError(
                f'{target}: exists already and is not a directory, not overwriting'
            )
        check_output_directory(target)  # said of the target, not of the hidden directory
        holder = partial_dir(target)
        _remove(holder)
        holder.mkdir(parents=False)
        temporary = holder / target.name
        mode = 'merge' if merge_into_dir else 'replace' if replace else ''
        self._targets.append((target, temporary, mode))
        return temporary

    def __enter__(self) -> AtomicOutputs:
        self._received: int | None = None
        if threading.current_thread() is threading.main_thread():
            for signum in (signal.SIGINT, *self._SIGNALS):
                self._old[signum] = signal.signal(signum, self._interrupt)
        return self

    def _interrupt(self, signum: int, frame: FrameType | None) -> None:
        """Remember the signal, then raise it (KeyboardInterrupt or :class:`Terminated`).

        Raised where Python swallows exceptions (a ``__del__``), it must still stop the commit.
        """
        self._received = signum
        if signum == signal.SIGINT:
            raise KeyboardInterrupt
        self._terminate(signum, frame)

    @staticmethod
    def _terminate(signum: int, _frame: FrameType | None) -> None:
        raise Terminated(signum)

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        try:
            if exc is None:
                blocked = self._block()
                try:
                    if self._received is not None:  # raised where it was swallowed
                        received = self._received
                        raise (
                            KeyboardInterrupt
                            if received == signal.SIGINT
                            else Terminated(received)
                        )
                    self._commit()
                except BaseException as err:
                    self._abort(err)
                    raise
                finally:
                    if blocked:  # a signal that came meanwhile is raised now, after the rename
                        signal.pthread_sigmask(signal.SIG_UNBLOCK, blocked)
            else:
                self._abort(exc)
        finally:
            for signum, handler in self._old.items():
                signal.signal(signum, handler)
            self._old.clear()

    def _block(self) -> set[int]:
        """Hold SIGINT and the handled signals back while the renames run (POSIX)."""
        if not hasattr(signal, 'pthread_sigmask'):  # pragma: no cover - Windows
            return set()
        wanted = {signal.SIGINT, *self._SIGNALS}
        signal.pthread_sigmask(signal.SIG_BLOCK, wanted)
        return wanted

    def _commit(self) -> None:
        for target, _, mode in self._targets:  # check all before renaming any
            taken = target.exists() or target.is_symlink()
            if taken and not (mode == 'merge' and target.is_dir()) and mode != 'replace':
                raise FileExistsError(f'{target}: exists already, not overwriting')
            if mode == 'replace' and target.is_dir():
                raise IsADirectoryError(f'{target}: is a directory')
        for target, temporary, mode in self._targets:
            if mode == 'merge' and target.is_dir():
                for item in sorted(temporary.iterdir()) if temporary.is_dir() else ():
                    dest = target / item.name
                    if dest.is_dir() and not item.is_dir():
                        raise FileExistsError(f'{dest}: is a directory')
                    os.replace(item, dest)
            elif mode == 'replace' and temporary.exists():
                os.replace(temporary, target)
            elif temporary.exists():
                os.rename(temporary, target)
        for target, _, _ in self._targets:
            _remove(partial_dir(target))
        self._targets.clear()

    def _abort(self, exc: BaseException) -> None:
        started = False  # whether any partial output was there to remove
        for target, temporary, _ in self._targets:
            started = started or temporary.exists()
            _remove(partial_dir(target))
        targets = list(dict.fromkeys([*self._announce, *(t for t, _, _ in self._targets)]))
        interrupted = isinstance(exc, (KeyboardInterrupt, Terminated))
        if targets and (interrupted or started):  # (an error before any output: its message)
            names = ', '.join(str(t) for t in targets)
            why = 'interrupted' if interrupted else 'failed'
            stderr = self._stderr or sys.stderr
            print(f'{why}: nothing written to {names} (partial output removed)', file=stderr)
            stderr.flush()
            exc.outputs_reported = True  # type: ignore[attr-defined]  # the CLI says no more
        self._targets.clear()
