"""Shared pieces of the command line: the Typer app, JSON output, error handling, signals and
the unit policy of options.

Exit codes: 0 success, 2 bad input (:class:`~braidsim.errors.InputError`, usage errors), 1 a
numerical, storage or I/O failure (with its cause and the path), 128 + N after signal N
(130 SIGINT, 143 SIGTERM, 129 SIGHUP). Every failure is one line on stderr, never a
traceback; an unexpected exception is reported as an internal error in one line (set
``BRAIDSIM_TRACEBACK=1`` to see the traceback).
"""

from __future__ import annotations

import errno
import io as _io
import json
import math
import os
import signal
import sys
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from functools import wraps
from typing import Any, TypeVar

import typer

from braidsim import io
from braidsim.errors import InputError, SimulationError, StoreError
from braidsim.io import json_safe

app = typer.Typer(
    name="braidsim",
    help="Carrier-track contact dynamics of maypole braiding machines.",
    add_completion=False,
    no_args_is_help=True,
    pretty_exceptions_enable=False,
    # help texts are plain text: "[s]", "[m/s]" are units, not rich markup
    rich_markup_mode=None,
)

F = TypeVar("F", bound=Callable[..., Any])
T = TypeVar("T")


class ClosedStream(_io.TextIOBase):
    """Stands in for a standard stream the process was started without (``braidsim run
    --json >&-``): Python then sets ``sys.stdout`` to None, and the command's first write
    was an AttributeError, reported as an internal error (or, for ``--version``, a
    traceback). Every write is an OSError naming the stream, which a verb reports as one
    line with exit code 1, as it does any output it cannot write."""

    def __init__(self, name: str) -> None:
        super().__init__()
        self.name = name

    def writable(self) -> bool:
        return True

    def write(self, text: str) -> int:
        raise OSError(
            errno.EBADF,
            f"{os.strerror(errno.EBADF)} (the command was started with it closed; what it "
            "prints had nowhere to go)",
            self.name,
        )


def _show_version(value: bool) -> None:
    if value:
        from braidsim.provenance import version

        sys.stdout.write(f"braidsim {version()}\n")
        raise typer.Exit(0)


@app.callback()
def _root(
    version: bool = typer.Option(
        False,
        "--version",
        callback=_show_version,
        is_eager=True,
        help="Print the version and exit.",
    ),
) -> None:
    """Carrier-track contact dynamics of maypole braiding machines."""


def print_json(obj: Any) -> None:
    """One strict JSON object on stdout, nothing else; it starts with ``braidsim_version``."""
    from braidsim.provenance import version

    if isinstance(obj, dict):
        obj = {"braidsim_version": version(), **obj}
    sys.stdout.write(json.dumps(json_safe(obj), allow_nan=False) + "\n")
    sys.stdout.flush()


def result_console() -> Any:
    """The console on which a command prints its results (stdout).

    Its tables are printed whole. rich fits a table to the console by folding its text
    cells and, where that is not enough, by cutting cells short (``1.0…`` for 1.0000); a
    piped output counts as 80 columns, so a wide table of numbers sent to a file lost them.
    On a terminal, a table that rich would cut is printed at the width that keeps every
    cell whole instead (the terminal wraps its lines), and one that folds is left as it is;
    piped or redirected, every table is printed wide enough that no word of a cell is
    folded or cut (text still wraps at its spaces), unless ``COLUMNS`` asks for a width.
    """
    import io

    from rich.console import Console
    from rich.measure import Measurement
    from rich.table import Table
    from rich.text import Text

    class _WholeTables(Console):
        def _cut_at(self, table: Table, width: int) -> bool:
            trial = Console(file=io.StringIO(), width=width, color_system=None)
            trial.print(table)
            return "…" in trial.file.getvalue()  # type: ignore[attr-defined]

        def _folds_at(self, table: Table, width: int) -> bool:
            """Whether rich, at ``width``, cuts a cell of ``table`` short or folds one of
            its words over two lines (a word of a cell missing from the printed text)."""
            trial = Console(file=io.StringIO(), width=width, color_system=None)
            trial.print(table)
            text = trial.file.getvalue()  # type: ignore[attr-defined]
            if "…" in text:
                return True
            for column in table.columns:
                for cell in column._cells:
                    # (a string cell as rich renders it: its markup read)
                    shown = cell if isinstance(cell, Text) else self.render_str(str(cell))
                    plain = shown.plain
                    if any(word not in text for word in plain.split()):
                        return True
            return False

        def _narrowest(self, table: Table, bad: Callable[[Table, int], bool]) -> int:
            """The narrowest width from the console's at which ``bad`` is false (a
            bisection up to the table's natural width: more width never cuts or folds
            more)."""
            unbounded = self.options.update_width(1 << 20)  # measured, not fitted
            low, high = self.width, max(self.width, Measurement.get(self, unbounded, table).maximum)
            while low < high:
                mid = (low + high) // 2
                low, high = (mid + 1, high) if bad(table, mid) else (low, mid)
            return high

        def _whole_width(self, table: Table) -> int:
            """The narrowest width at which rich cuts no cell of ``table`` short."""
            return self._narrowest(table, self._cut_at)

        def _unfolded_width(self, table: Table) -> int:
            """The narrowest width at which no cell of ``table`` is cut or has a word
            folded."""
            return self._narrowest(table, self._folds_at)

        def print(self, *objects: Any, **kwargs: Any) -> None:
            tables = [o for o in objects if isinstance(o, Table)]
            if not tables:
                super().print(*objects, **kwargs)
                return
            if self.is_terminal or os.environ.get("COLUMNS"):  # (a width asked for: kept)
                if not any(self._cut_at(t, self.width) for t in tables):
                    super().print(*objects, **kwargs)
                    return
                wide = max(self._whole_width(t) for t in tables)
            else:
                # piped or redirected: wide enough that no word of a cell is folded (a
                # number split over two lines of a file reads as two numbers), text
                # still wrapped at its spaces; and no cell cut short
                wide = max(self._unfolded_width(t) for t in tables)
            width = self.width
            self.width = wide
            try:
                super().print(*objects, **{**kwargs, "crop": False})
            finally:
                self.width = width

    return _WholeTables()


def fail(message: str, code: int) -> None:
    """One line on stderr and exit with ``code``."""
    line = " ".join(str(message).split())  # one line, whatever the message holds
    sys.stderr.write(f"braidsim: error: {line}\n")
    sys.stderr.flush()
    raise typer.Exit(code)


_NOTICES: list[str] = []


def notice(message: str) -> None:
    """An informational line for stderr (stdout stays clean for ``--json``).

    Notices are held until the command's input is accepted (:func:`flush_notices`, called
    before long work and at the end of every command): a command refused for bad input
    prints its one error line only.
    """
    _NOTICES.append(f"braidsim: note: {message}\n")


def flush_notices() -> None:
    """Write the notices held so far to stderr."""
    while _NOTICES:
        sys.stderr.write(_NOTICES.pop(0))
    sys.stderr.flush()


class Interrupted(KeyboardInterrupt):
    """SIGINT, SIGTERM or SIGHUP received: handled like Ctrl-C (see :func:`signals_handled`)."""

    def __init__(self, signum: int) -> None:
        super().__init__(signal.Signals(signum).name)
        self.signum = signum


def _loaded(name: str) -> Any:
    """The module ``name`` if it is fully imported, else None; never imports it.

    A signal handler runs between two bytecodes of whatever the main thread does, which may
    be the first import of that very module: ``import`` in the handler then hands back the
    half-executed module (its names not yet defined), and the handler failed on it
    (``partially initialized module 'multiprocessing' has no attribute
    'active_children'``, reported as an internal error instead of the interruption).
    """
    mod = sys.modules.get(name)
    if mod is None or getattr(getattr(mod, "__spec__", None), "_initializing", False):
        return None
    return mod


def _end_children() -> None:
    """Kill this process's worker processes (pools, a local Dask cluster) so none outlives
    an interrupted command; a pool then reports them dead instead of waiting for them.

    Only through a fully imported :mod:`multiprocessing` (:func:`_loaded`): while it is
    not, no worker can have been started by it.
    """
    process = _loaded("multiprocessing.process")  # where active_children is defined
    active = getattr(process, "active_children", None)
    if active is None:
        return
    for child in active():
        child.kill()


def _quiet_shutdown() -> None:
    """Silence what the libraries say while the process stops on a signal: its one line is
    the command's. A local Dask cluster whose workers were just killed logs its closed
    connections and lost tasks (with tracebacks) as it closes, and an asyncio coroutine cut
    off by the signal (zarr's or Dask's) warns that it was never awaited when it is freed:
    in 4 of 25 interrupted sweeps on 2 workers before this."""
    # (taken only if already imported, :func:`_loaded`: not loaded, nothing has logged and
    # no cluster is there to silence; numpy, always imported before, imports warnings)
    logging = _loaded("logging")
    if logging is not None:
        logging.disable(logging.CRITICAL)
    warnings = _loaded("warnings")
    if warnings is not None:
        warnings.filterwarnings(
            "ignore", message="coroutine .* was never awaited", category=RuntimeWarning
        )


_RECEIVED: list[Interrupted] = []  # the signal this command received, once one arrived


_MAIN_PID: list[int] = []  # the process whose command handles the signals


def _on_signal(signum: int, frame: Any) -> None:
    if _MAIN_PID and os.getpid() != _MAIN_PID[0]:
        # a worker forked with this handler (a pool, a sweep's processes): it ends quietly
        # on the signal, as it would without the handler; the command reports it
        signal.signal(signum, signal.SIG_DFL)
        os.kill(os.getpid(), signum)
        return
    # ignore further signals while we stop: the first one decides the exit code
    for sig in _SIGNALS:
        signal.signal(sig, signal.SIG_IGN)
    # recorded first: whatever happens next, the command ends as interrupted by it
    # (signal_decides), not on a failure of the clean-up below
    stop = Interrupted(signum)
    _RECEIVED.append(stop)
    try:
        _quiet_shutdown()
        _end_children()
    except Exception:  # (a clean-up that fails must not take the signal's place)
        pass
    raise stop


@contextmanager
def signal_decides() -> Iterator[None]:
    """Within the block, a failure that follows a signal is reported as the signal.

    The handler raises :class:`Interrupted` wherever the main thread is, and Python drops
    an exception raised inside a weakref callback or a ``__del__`` ("Exception ignored
    in ..."). The command then went on with its workers killed and failed on them (a sweep
    on a local Dask cluster: "chunk 2 failed after 2 retries: FutureCancelledError()",
    exit code 1, in 1 of 30 SIGTERMs): the failure is the interruption's, and so are its
    line and exit code."""
    try:
        yield
    except (typer.Exit, typer.Abort):  # the command's own ending (click's are Exceptions)
        raise
    except Exception:
        if not _RECEIVED:
            raise
        raise _RECEIVED[0] from None
    if _RECEIVED:
        # the interruption was dropped where it was raised and the command went on to its
        # end: it still ends as interrupted (its outputs, whole, are named then)
        raise _RECEIVED[0]


def _unraisable(hook: Any) -> Any:
    """A ``sys.unraisablehook`` that drops the signal's own exception where Python cannot
    raise it (a weakref callback, a ``__del__``, a ctypes callback of the compiler) instead
    of printing its traceback: :func:`signal_decides` ends the command on it."""

    def quiet(unraisable: Any) -> None:
        if isinstance(unraisable.exc_value, Interrupted):
            return
        hook(unraisable)

    return quiet


_SIGNALS = (signal.SIGINT, signal.SIGTERM, signal.SIGHUP)


@contextmanager
def signals_handled() -> Iterator[None]:
    """SIGINT, SIGTERM and SIGHUP raise :class:`Interrupted` in the main thread (after killing
    the worker processes), so every verb unwinds the same way: temporary outputs removed,
    stores left resumable, one line on stderr."""
    import threading

    if threading.current_thread() is not threading.main_thread():
        yield
        return
    old = {sig: signal.getsignal(sig) for sig in _SIGNALS}
    old_hook = sys.unraisablehook
    _RECEIVED.clear()
    _MAIN_PID[:] = [os.getpid()]
    sys.unraisablehook = _unraisable(old_hook)
    for sig in _SIGNALS:
        signal.signal(sig, _on_signal)
    try:
        with signal_decides():
            yield
    finally:
        for sig, h in old.items():
            signal.signal(sig, h)
        sys.unraisablehook = old_hook


def _os_error_text(exc: OSError) -> str:
    why = exc.strerror or (str(exc).splitlines()[0][:200] if str(exc) else "")
    why = why or exc.__class__.__name__
    hint = ""
    if exc.errno in (28, 27, 122):  # ENOSPC, EFBIG, EDQUOT
        hint = "; free space (or raise the file-size limit), then run again"
    # (no file named: said so, rather than a guess of which one, input or output)
    path = exc.filename if exc.filename is not None else "reading or writing a file"
    return f"{path}: {why}{hint}"


def _name_too_long_text(exc: OSError, names: dict[str, str], given: dict[str, Any]) -> str:
    """One line for a path whose name the file system refuses as too long, naming the
    option or argument that gave it where one did (the path itself, or a file under it)."""
    path = str(exc.filename) if exc.filename is not None else ""
    head = path
    for name, value in given.items():
        if isinstance(value, str | os.PathLike) and str(value) and path.startswith(str(value)):
            head = names.get(name, name.upper())
            break
    return (
        f"{head}: {io.shown_path(path)!r} ({len(os.fsencode(path))} bytes) is a name too long "
        "for the file system; allowed names of at most 255 bytes a part"
    )


def _written_since(first: int) -> str:
    """What an interrupted command leaves: the outputs it had put in place (each whole),
    or none."""
    done = list(dict.fromkeys(str(p) for p in io.WRITTEN[first:]))
    if not done:
        return "no output was written"
    more = f" and {len(done) - 1} more" if len(done) > 1 else ""
    return f"the output {done[-1]!r}{more} had been written whole before it"


def option_names(func: Any) -> dict[str, str]:
    """The command-line option of each option parameter of a verb function (``cycles`` ->
    ``--cycles``, ``json_`` -> ``--json``): its declared long name, else Typer's default."""
    import typing

    from typer.models import OptionInfo

    out: dict[str, str] = {}
    try:
        hints = typing.get_type_hints(func, include_extras=True)
    except Exception:  # (an annotation only a type checker can read: the names stay the API's)
        return out
    for name, hint in hints.items():
        for info in typing.get_args(hint)[1:]:
            if isinstance(info, OptionInfo):
                # (in ``Annotated``, Typer reads a first argument "--name" as a declaration)
                first = [info.default] if isinstance(info.default, str) else []
                decls = [d for d in [*first, *(info.param_decls or ())] if d.startswith("--")]
                out[name] = max(decls, key=len) if decls else "--" + name.replace("_", "-")
    return out


def spec_loaded(load: Callable[[Any], T], path: Any) -> T:
    """``load(path)`` for a verb's SPEC file, its input errors marked as the file's: a bad
    ``duration`` in the file stays ``duration: ...`` when ``--duration`` is given too
    (:func:`option_named` had renamed it after the option, which the user had typed right)."""
    try:
        return load(path)
    except InputError as exc:
        exc.in_spec_file = True  # type: ignore[attr-defined]
        raise


def option_named(
    text: str, names: dict[str, str], given: dict[str, Any], in_spec_file: bool = False
) -> str:
    """An input error's leading parameter name as the command's option: the API says
    ``cycles: 0 is out of range ...``, the command line ``--cycles: 0 is out of range
    ...``, so that the line names what was typed. Only for an option that has a value
    (``given``: the verb's arguments) and an error not raised by the SPEC file's reader
    (``in_spec_file``, :func:`spec_loaded`): a spec file's ``duration`` stays
    ``duration: ...``, and a scenario key, ``track.clearance: ...``, is no option."""
    if in_spec_file:
        return text
    head, sep, rest = text.partition(": ")
    if sep and head in names and given.get(head) is not None:
        return f"{names[head]}: {rest}"
    return text


def guarded(func: F) -> F:
    """Turn braidsim's errors into one-line messages and exit codes (2 input, 1 failures)."""

    @wraps(func)
    def wrapper(*args: Any, **kwargs: Any) -> Any:
        _NOTICES.clear()
        first = len(io.WRITTEN)  # the outputs this command puts in place come after
        try:
            with signals_handled():
                out = func(*args, **kwargs)
            flush_notices()
            return out
        except InputError as exc:
            _NOTICES.clear()  # the error line names the value and its unit
            in_file = getattr(exc, "in_spec_file", False)
            fail(option_named(str(exc), option_names(func), kwargs, in_file), 2)
        except SimulationError as exc:
            flush_notices()
            fail(f"simulation failed: {exc}", 1)
        except StoreError as exc:
            fail(str(exc), 1)
        except Interrupted as exc:
            fail(f"interrupted by {exc.args[0]}; {_written_since(first)}", 128 + exc.signum)
        except KeyboardInterrupt:
            fail(f"interrupted by SIGINT; {_written_since(first)}", 130)
        except OSError as exc:
            if exc.errno == errno.ENAMETOOLONG:
                # a path the user typed that no file system takes: their input, not a failure
                fail(_name_too_long_text(exc, option_names(func), kwargs), 2)
            fail(_os_error_text(exc), 1)
        except MemoryError:
            fail("out of memory; reduce the size of the work (see the limits in the docs)", 1)
        except (typer.Exit, typer.Abort, SystemExit, typer.TyperException):
            raise  # exit codes and usage errors: run_app answers them
        except Exception as exc:
            if os.environ.get("BRAIDSIM_TRACEBACK"):
                raise
            text = str(exc).splitlines()[0][:200] if str(exc) else ""
            fail(
                f"internal error: {exc.__class__.__name__}: {text} (a bug: please report it "
                "with the command; BRAIDSIM_TRACEBACK=1 shows the traceback)",
                1,
            )
        return None

    return wrapper  # type: ignore[return-value]


def quantity_option(option: str, value: Any, unit: str) -> float:
    """The unit policy of the command line for one dimensional option.

    ``value`` is a number or a string with a unit (``"1 nm"``, ``"0.5 m/s"``); a unit
    string is converted to ``unit`` (SI). A bare number is taken as SI and, unless it is 0
    (which needs no unit) or ``unit`` is dimensionless, a one-line notice on stderr says
    which unit was assumed.
    """
    from braidsim.units import parse_quantity

    v, bare = parse_quantity(option, value, unit)
    if bare and unit and v != 0 and math.isfinite(v):
        notice(f"{option} {value} taken as {v:g} {unit} (SI); write e.g. '{value} {unit}'")
    return v


def _has_bare_number(value: Any) -> bool:
    from braidsim.units import is_number

    if is_number(value):
        return value != 0
    if isinstance(value, list | tuple):
        return any(_has_bare_number(v) for v in value)
    if isinstance(value, dict):
        return any(_has_bare_number(v) for v in value.values())
    return False


def parse_sets(sets: list[str] | None) -> dict[str, Any]:
    """``--set KEY=VALUE`` options to an overrides mapping."""
    from braidsim.params import SCHEMA, parse_assignment, parse_set_value

    out: dict[str, Any] = {}
    for item in sets or []:
        key, value = parse_assignment(item)
        parsed = parse_set_value(key, value)
        unit = SCHEMA[key].unit
        if unit and SCHEMA[key].kind != "choice" and _has_bare_number(parsed):
            example = value if isinstance(parsed, int | float) else "VALUE"
            notice(
                f"--set {key}={value}: a bare number is taken in SI ({unit}); "
                f"write the unit, e.g. '{example} {unit}'"
            )
        out[key] = parsed
    return out


def run_app(argv: list[str] | None) -> int:
    """Run the Typer app; return the exit code.

    Usage errors (unknown option, missing argument) become one line on stderr and exit code 2,
    like bad parameter values.
    """
    try:
        # with standalone_mode=False typer returns the code of a typer.Exit instead of raising
        rv = app(args=argv, standalone_mode=False)
        if isinstance(rv, int):
            return rv
    except typer.Exit as exc:
        return int(exc.exit_code or 0)
    except typer.Abort:
        sys.stderr.write("braidsim: error: aborted\n")
        return 130
    except typer.TyperException as exc:
        message = exc.format_message() if hasattr(exc, "format_message") else str(exc)
        line = " ".join(str(message).split())
        sys.stderr.write(f"braidsim: error: {line}\n")
        return 2
    except KeyboardInterrupt:  # a signal outside a verb (while parsing the arguments)
        sys.stderr.write("braidsim: error: interrupted\n")
        return 130
    except OSError as exc:  # outside a verb: --version on a closed stdout
        sys.stderr.write(f"braidsim: error: {' '.join(_os_error_text(exc).split())}\n")
        return 1
    return 0
