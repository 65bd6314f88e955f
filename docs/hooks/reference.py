"""MkDocs hook: fill docs/cli.md from the command line itself and the scenario schema.

The page carries two regions, each between a start and an end marker:
``<!-- braidsim:commands -->`` ... ``<!-- /braidsim:commands -->`` and
``<!-- braidsim:keys -->`` ... ``<!-- /braidsim:keys -->``. At build time this hook replaces
what lies between them with tables generated from the Typer/Click command objects (every
command, argument and option with its help text and default) and from
``braidsim.params.SCHEMA`` (every scenario key with its unit, default and allowed range), so
the site cannot drift from the code. The generated text is also committed between the
markers, so that the page reads whole in the repository (GitHub shows it, the README links
it); ``python docs/hooks/reference.py`` writes it again after a change to the command line or
the schema, and tests/unit/test_cli_page.py fails while the committed text is out of date.
It is read by MkDocs (``hooks:`` in mkdocs.yml), not imported by the package.
"""

from __future__ import annotations

import math
import sys
from pathlib import Path
from typing import Any

COMMANDS_MARK = "<!-- braidsim:commands -->"
KEYS_MARK = "<!-- braidsim:keys -->"
#: the page the regions are on
PAGE = Path(__file__).resolve().parents[1] / "cli.md"


def _cell(text: Any) -> str:
    """Text safe inside a Markdown table cell."""
    return " ".join(str(text).split()).replace("|", "\\|")


def _default(value: Any) -> str:
    if value is None or value == () or value == []:
        return ""
    if isinstance(value, float):
        if math.isinf(value):
            return "inf"
        return f"{value:g}"
    return str(value)


def _is_argument(param: Any) -> bool:
    # Typer's parameters subclass those of the click it bundles, so test the kind by name
    return getattr(param, "param_type_name", "") == "argument"


def commands_markdown() -> str:
    """One section per ``braidsim`` command: usage line, help text, parameters table."""
    import click
    import typer

    from braidsim.cli import _register
    from braidsim.cli.common import app

    _register()
    group = typer.main.get_command(app)
    ctx = click.Context(group, info_name="braidsim")
    out: list[str] = []
    for name in sorted(group.list_commands(ctx)):  # type: ignore[attr-defined]
        cmd = group.get_command(ctx, name)  # type: ignore[attr-defined]
        args = [p.name.upper() for p in cmd.params if _is_argument(p) and p.name]
        usage = " ".join(["[OPTIONS]", *args])
        out.append(f"### braidsim {name}\n")
        # a "text" block: a usage line, not a command (the docs tests run shell blocks)
        out.append(f"```text\nbraidsim {name} {usage}\n```\n")
        out.append(" ".join((cmd.help or "").split()) + "\n")
        rows = []
        for p in cmd.params:
            if p.name == "help":
                continue
            names = ", ".join(f"`{o}`" for o in (*p.opts, *p.secondary_opts))
            if _is_argument(p):
                names = f"`{p.name.upper()}`" if p.name else names
            helptext = getattr(p, "help", None) or ""
            default = "" if p.required else _default(p.default)
            rows.append(
                f"| {names} | {_cell(helptext)} | {_cell(default)} | "
                f"{'yes' if p.required else ''} |"
            )
        if rows:
            out.append("| parameter | meaning | default | required |")
            out.append("|---|---|---|---|")
            out.extend(rows)
        out.append("")
    return "\n".join(out)


def keys_markdown() -> str:
    """A table of every scenario key of :data:`braidsim.params.SCHEMA`, grouped by section."""
    from braidsim.params import SCHEMA

    out: list[str] = []
    section = None
    for key, spec in SCHEMA.items():
        head = key.split(".", 1)[0]
        if head != section:
            section = head
            out.append(f"\n#### `{head}`\n")
            out.append("| key | unit (SI) | default | allowed | meaning |")
            out.append("|---|---|---|---|---|")
        out.append(
            f"| `{key}` | {_cell(spec.unit) or '-'} | {_cell(_default(spec.default))} | "
            f"{_cell(spec.range_text())} | {_cell(spec.doc)} |"
        )
    return "\n".join(out) + "\n"


def _end(mark: str) -> str:
    """The end marker of the region that ``mark`` starts (``<!-- /braidsim:... -->``)."""
    return mark.replace("<!-- ", "<!-- /", 1)


def fill(markdown: str) -> str:
    """``markdown`` with each region (start marker, generated text, end marker) generated
    again; a start marker without its end marker gets the region whole after it."""
    for mark, make in ((COMMANDS_MARK, commands_markdown), (KEYS_MARK, keys_markdown)):
        start = markdown.find(mark)
        if start < 0:
            continue
        end_mark = _end(mark)
        end = markdown.find(end_mark, start)
        stop = start + len(mark) if end < 0 else end + len(end_mark)
        region = f"{mark}\n\n{make().strip()}\n\n{end_mark}"
        markdown = markdown[:start] + region + markdown[stop:]
    return markdown


def on_page_markdown(markdown: str, page: Any, config: Any, files: Any) -> str:
    """MkDocs event: generate the regions of the page that carries them."""
    return fill(markdown)


def main() -> int:
    """Write the regions of docs/cli.md again (``python docs/hooks/reference.py``); print
    whether they changed."""
    old = PAGE.read_text(encoding="utf-8")
    new = fill(old)
    if new == old:
        print(f"{PAGE}: up to date")
        return 0
    PAGE.write_text(new, encoding="utf-8")
    print(f"{PAGE}: written")
    return 0


if __name__ == "__main__":
    sys.exit(main())
