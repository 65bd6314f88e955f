"""Checks shared by the TOML spec readers (sweep, machine, design): one-line errors that name
the key, the closest known key and the allowed ones."""

from __future__ import annotations

import difflib
import tomllib
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from braidsim.errors import InputError


def closest_hint(word: str, choices: Sequence[str]) -> str:
    """`` (did you mean 'x'?)`` for the closest of ``choices``, or an empty string."""
    close = difflib.get_close_matches(word, list(choices), n=1, cutoff=0.5)
    return f" (did you mean {close[0]!r}?)" if close else ""


def check_keys(where: str, table: Mapping[str, Any], allowed: Sequence[str]) -> None:
    """Raise :class:`InputError` for the first key of ``table`` not in ``allowed``."""
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


def read_toml_file(path: str | Path, kind: str) -> dict[str, Any]:
    """The table of a spec file; an :class:`InputError` for a missing file or bad TOML.

    ``kind`` names the spec in the message (e.g. "sweep spec").
    """
    p = Path(path)
    if not p.is_file():
        raise InputError(f"SPEC: {str(p)!r} is not a file; allowed a {kind} TOML file")
    try:
        return tomllib.loads(p.read_text())
    except tomllib.TOMLDecodeError as exc:
        raise InputError(f"{p}: malformed TOML ({exc})") from None
