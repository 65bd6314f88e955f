"""The ``braidsim`` command line: a thin layer over the public API.

Each verb lives in its own module and registers itself on :data:`app`; this file only wires
them together and maps errors to exit codes (2 bad input, 1 numerical failure).
"""

from __future__ import annotations

import sys

from braidsim.cli.common import app


def _register() -> None:
    # Importing a verb module registers its command on `app`.
    from braidsim.cli import (  # noqa: F401
        analysis,
        continue_,
        design,
        machine,
        paper,
        run,
        sweep,
    )


def main(argv: list[str] | None = None) -> None:
    """Entry point of the ``braidsim`` command."""
    _register()
    from braidsim.cli.common import run_app

    sys.exit(run_app(argv))


__all__ = ["app", "main"]
