"""Checks shared by the TOML spec readers (sweep, machine, design): one-line errors that name
the key, the closest known key and the allowed ones."""

from __future__ import annotations

import difflib
import math
import tomllib
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from braidsim.errors import InputError


def closest_hint(word: str, choices: Sequence[str]) -> str:
    """`` (did you mean 'x'?)`` for the closest of ``choices``, or an empty string."""
    close = difflib.get_close_matches(word, list(choices), n=1, cutoff=0.5)
    return f" (did you mean {close[0]!r}?)" if close else ""


def check_choice(where: str, value: Any, choices: Sequence[str]) -> None:
    """Raise :class:`InputError` unless ``value`` is one of ``choices`` (``where``: the
    entry's name), with the closest choice as a hint."""
    if value not in choices:
        raise InputError(
            f"{where}: {value!r} is not allowed{closest_hint(str(value), choices)}; "
            f"allowed {', '.join(choices)}"
        )


def check_keys(where: str, table: Mapping[str, Any], allowed: Sequence[str]) -> None:
    """Raise :class:`InputError` for the first key of ``table`` not in ``allowed`` (or for a
    ``table`` that is no table: a spec handed to the API as something else)."""
    expect_table(where.rstrip(".") or "spec", table)
    for k in table:
        if k not in allowed:
            raise InputError(
                f"{where}{k}: unknown key{closest_hint(k, allowed)}; allowed {', '.join(allowed)}"
            )


def expect_table(where: str, value: Any) -> Mapping[str, Any]:
    """``value`` if it is a TOML table, else an :class:`InputError` naming ``where``."""
    if not isinstance(value, Mapping):
        raise InputError(f"{where}: expected a table, got {value!r}")
    return value


#: largest spec or scenario file read (a spec is a few kilobytes)
MAX_FILE_BYTES = 10_000_000


def read_text(path: str | Path, what: str = "SPEC") -> str:
    """The UTF-8 text of a spec or scenario file, with one-line errors naming the path.

    Raises
    ------
    InputError
        Not a file, unreadable, larger than :data:`MAX_FILE_BYTES`, or not UTF-8 (TOML files
        are UTF-8 by definition).
    """
    p = Path(path)
    if not p.is_file():
        raise InputError(f"{what}: {str(p)!r} is not a file; allowed a TOML file")
    try:
        size = p.stat().st_size
        if size > MAX_FILE_BYTES:
            raise InputError(
                f"{p}: {size} bytes is too large for a TOML spec; allowed <= {MAX_FILE_BYTES}"
            )
        data = p.read_bytes()
    except OSError as exc:
        raise InputError(f"{p}: cannot read ({exc.strerror or exc})") from None
    try:
        # (a byte-order mark, which Windows editors write, is not TOML; it is invisible to
        # the user, so it is dropped rather than reported as malformed TOML at line 1)
        return data.decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        raise InputError(
            f"{p}: not UTF-8 text (byte {data[exc.start]:#04x} at offset {exc.start}); "
            "allowed a UTF-8 TOML file (save it as UTF-8)"
        ) from None


def toml_float(text: str) -> float:
    """``parse_float`` of the TOML reader: a finite literal too large for a 64-bit float
    (``1e400``) is an error instead of a silent infinity."""
    value = float(text)
    if math.isinf(value) and "inf" not in text:
        raise ValueError(f"{text} is too large for a 64-bit float (|x| < 1.8e308)")
    return value


def parse_toml(text: str, origin: str) -> dict[str, Any]:
    """Parse TOML text; an :class:`InputError` naming ``origin`` for malformed or too deeply
    nested input (the standard parser recurses once per level of nesting)."""
    try:
        return tomllib.loads(text, parse_float=toml_float)
    except tomllib.TOMLDecodeError as exc:
        raise InputError(f"{origin}: malformed TOML ({exc})") from None
    except RecursionError:
        raise InputError(
            f"{origin}: arrays or tables nested too deeply; allowed a few levels"
        ) from None
    except ValueError as exc:  # e.g. an integer literal of more than 4300 digits
        raise InputError(f"{origin}: malformed TOML ({str(exc)[:80]})") from None


def read_toml_file(path: str | Path, kind: str) -> dict[str, Any]:
    """The table of a spec file; an :class:`InputError` for a missing file or bad TOML.

    ``kind`` names the spec in the message (e.g. "sweep spec").
    """
    p = Path(path)
    if not p.is_file():
        raise InputError(f"SPEC: {str(p)!r} is not a file; allowed a {kind} TOML file")
    table = parse_toml(read_text(p), str(p))
    if not table:
        raise InputError(f"{p}: the {kind} is empty; allowed a {kind} TOML file with its keys")
    return table
