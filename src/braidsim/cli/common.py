"""Shared pieces of the command line: the Typer app, JSON output, error handling."""

from __future__ import annotations

import json
import math
import sys
from collections.abc import Callable
from functools import wraps
from typing import Any, TypeVar

import typer

from braidsim.errors import InputError, SimulationError

app = typer.Typer(
    name="braidsim",
    help="Carrier-track contact dynamics of maypole braiding machines.",
    add_completion=False,
    no_args_is_help=True,
    pretty_exceptions_enable=False,
)

F = TypeVar("F", bound=Callable[..., Any])


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


def _clean(obj: Any) -> Any:
    """NaN and inf become null so that the output is strict JSON."""
    if isinstance(obj, float):
        return obj if math.isfinite(obj) else None
    if isinstance(obj, dict):
        return {k: _clean(v) for k, v in obj.items()}
    if isinstance(obj, list | tuple):
        return [_clean(v) for v in obj]
    if hasattr(obj, "item") and callable(obj.item):  # numpy scalars
        return _clean(obj.item())
    return obj


def print_json(obj: Any) -> None:
    """One strict JSON object on stdout, nothing else; it starts with ``braidsim_version``."""
    from braidsim.provenance import version

    if isinstance(obj, dict):
        obj = {"braidsim_version": version(), **obj}
    sys.stdout.write(json.dumps(_clean(obj), allow_nan=False) + "\n")
    sys.stdout.flush()


def fail(message: str, code: int) -> None:
    """One line on stderr and exit with ``code``."""
    sys.stderr.write(f"braidsim: error: {message}\n")
    raise typer.Exit(code)


def guarded(func: F) -> F:
    """Turn braidsim's errors into one-line messages and exit codes (2 input, 1 numerics)."""

    @wraps(func)
    def wrapper(*args: Any, **kwargs: Any) -> Any:
        try:
            return func(*args, **kwargs)
        except InputError as exc:
            fail(str(exc), 2)
        except SimulationError as exc:
            fail(f"simulation failed: {exc}", 1)
        except KeyboardInterrupt:
            fail("interrupted", 130)
        return None

    return wrapper  # type: ignore[return-value]


def parse_sets(sets: list[str] | None) -> dict[str, Any]:
    """``--set KEY=VALUE`` options to an overrides mapping."""
    from braidsim.params import parse_assignment, parse_set_value

    out: dict[str, Any] = {}
    for item in sets or []:
        key, value = parse_assignment(item)
        out[key] = parse_set_value(key, value)
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
        sys.stderr.write(f"braidsim: error: {message}\n")
        return 2
    return 0
