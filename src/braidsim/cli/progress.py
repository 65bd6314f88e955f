"""Progress displays of the command line, on stderr, and SIGTERM handling for worker pools.

Progress is shown only where someone watches: when stderr is a terminal and the verb was not
asked for ``--json``, so that piped or captured output stays exactly what it was (stdout one
JSON object, stderr empty on success).
"""

from __future__ import annotations

import signal
import sys
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from types import FrameType
from typing import Any

#: what the first call of the integrator says while numba compiles it
COMPILE_NOTE = "compiling the integrator (about a minute, once; cached afterwards)"


def enabled(quiet: bool = False) -> bool:
    """Whether to draw progress: not ``quiet`` (``--json``) and stderr is a terminal."""
    if quiet:
        return False
    try:
        return sys.stderr.isatty()
    except (AttributeError, ValueError):
        return False


#: the compiled entry point of the solver: (file under braidsim/, function name) (the check
#: must not import it)
ENTRY_POINTS = (("core/solver/loop.py", "integrate"),)


def kernel_needs_compile() -> bool:
    """True when numba's cache holds no usable compiled integrator, i.e. the first run will
    compile it (about 50 s of CPU for `braidsim run` on 2 cores).

    Reads numba's cache index of the integrator's entry point (:data:`ENTRY_POINTS`) from
    the file system, as numba does: in ``NUMBA_CACHE_DIR`` when set, else in ``__pycache__``
    beside the source; an index whose source stamp no longer matches the file, or of another
    numba version, counts as absent. The compiled modules are not imported for this. Any
    surprise in numba's cache format gives False: the note is then simply not shown.
    """
    try:
        import pickle
        from pathlib import Path

        import numba
        from numba.core import caching, config

        import braidsim

        root = Path(braidsim.__file__).parent
        found = [(root / rel, fn) for rel, fn in ENTRY_POINTS if (root / rel).is_file()]
        if not found:
            return False
        src, fn = found[0]
        cache_dir = getattr(config, "CACHE_DIR", "")
        if cache_dir:
            sub = caching.UserProvidedCacheLocator.get_suitable_cache_subpath(str(src))
            cache = Path(cache_dir) / sub
        else:
            cache = src.parent / "__pycache__"
        st = src.stat()
        stamp = caching._hash_source_file(str(src), st.st_mtime, st.st_size)
        for index in cache.glob(f"{src.stem}.{fn}-*.nbi"):
            with open(index, "rb") as f:
                if pickle.load(f) != numba.__version__:
                    continue
                saved, overloads = pickle.loads(f.read())
            if saved == stamp and overloads:
                return False
        return True
    except Exception:
        return False


def _console() -> Any:
    from rich.console import Console

    return Console(stderr=True)


@contextmanager
def progress_status(message: str, quiet: bool = False) -> Iterator[None]:
    """A spinner with ``message`` on stderr while the block runs (only when :func:`enabled`).

    When the integrator will be compiled first, the spinner says so.
    """
    if not enabled(quiet):
        yield
        return
    if kernel_needs_compile():
        message = f"{COMPILE_NOTE}; then {message}"
    with _console().status(message):
        yield


@contextmanager
def progress_bar(
    description: str, total: int, quiet: bool = False
) -> Iterator[Callable[[int], None]]:
    """A progress bar on stderr; yields ``advance(n)`` to call as work completes.

    Disabled (``advance`` does nothing) unless :func:`enabled`.
    """

    def nothing(n: int = 1) -> None:
        return None

    if not enabled(quiet):
        yield nothing
        return
    from rich.progress import (
        BarColumn,
        MofNCompleteColumn,
        Progress,
        TextColumn,
        TimeElapsedColumn,
        TimeRemainingColumn,
    )

    if kernel_needs_compile():
        description = f"{description} (first: {COMPILE_NOTE})"
    with Progress(
        TextColumn("{task.description}"),
        BarColumn(),
        MofNCompleteColumn(),
        TimeElapsedColumn(),
        TimeRemainingColumn(),
        console=_console(),
        transient=True,
    ) as prog:
        task = prog.add_task(description, total=total)

        def advance(n: int = 1) -> None:
            prog.advance(task, n)

        yield advance


@contextmanager
def progress_simulated(
    message: str, t_start: float, t_end: float, quiet: bool = False
) -> Iterator[None]:
    """A spinner with ``message`` on stderr that becomes a bar of simulated time [s] with an
    estimate of the time left, for a run from ``t_start`` to ``t_end`` (only when
    :func:`enabled`). The compiled loop hands control back to Python every few tens of
    thousands of steps; each time, the bar moves to the run's time
    (:data:`braidsim.core.driver.PAUSE_HOOK`). A short run ends before it ever moves.
    """
    if not enabled(quiet):
        yield
        return
    from rich.progress import (
        BarColumn,
        Progress,
        SpinnerColumn,
        TaskProgressColumn,
        TextColumn,
        TimeElapsedColumn,
        TimeRemainingColumn,
    )

    from braidsim.core.driver import PAUSE_HOOK

    if kernel_needs_compile():
        message = f"{COMPILE_NOTE}; then {message}"
    span = max(t_end - t_start, 0.0)
    with Progress(
        SpinnerColumn(),
        TextColumn("{task.description}"),
        BarColumn(),
        TaskProgressColumn(),
        TimeElapsedColumn(),
        TimeRemainingColumn(),
        console=_console(),
        transient=True,
    ) as prog:
        task = prog.add_task(message, total=span or None)

        def moved(t: float) -> None:
            prog.update(task, completed=min(max(t - t_start, 0.0), span))

        token = PAUSE_HOOK.set(moved)
        try:
            yield
        finally:
            PAUSE_HOOK.reset(token)


@contextmanager
def sigterm_as_interrupt() -> Iterator[None]:
    """Within the block, SIGTERM raises KeyboardInterrupt as SIGINT does.

    Verbs that start worker processes catch KeyboardInterrupt to stop their workers
    (:func:`braidsim.analysis.runs.run_steady_states`); without this a ``kill PID`` would
    end the parent and leave the workers running until they finish their share. Only in the
    main thread (Python delivers signals there); elsewhere the block runs unchanged.
    """
    import threading

    if threading.current_thread() is not threading.main_thread():
        yield
        return

    from braidsim.cli.common import _on_signal

    if signal.getsignal(signal.SIGTERM) is _on_signal:
        # the command line's own handler (cli.common.signals_handled) is in place: it stops
        # the workers and raises a KeyboardInterrupt that keeps the signal's exit code
        yield
        return

    def handler(signum: int, frame: FrameType | None) -> None:
        raise KeyboardInterrupt

    previous = signal.signal(signal.SIGTERM, handler)
    try:
        yield
    finally:
        signal.signal(signal.SIGTERM, previous)
