"""MkDocs hook: fill docs/cli.md from the command line itself and the scenario schema.

The page carries two markers, ``<!-- braidsim:commands -->`` and ``<!-- braidsim:keys -->``.
At build time this hook replaces them with tables generated from the Typer/Click command
objects (every command, argument and option with its help text and default) and from
``braidsim.params.SCHEMA`` (every scenario key with its unit, default and allowed range), so
the reference cannot drift from the code. It is read by MkDocs (``hooks:`` in mkdocs.yml),
not imported by the package.
"""

from __future__ import annotations

import math
from typing import Any

COMMANDS_MARK = "<!-- braidsim:commands -->"
KEYS_MARK = "<!-- braidsim:keys -->"


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
        out.append(f"```\nbraidsim {name} {usage}\n```\n")
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


def on_page_markdown(markdown: str, page: Any, config: Any, files: Any) -> str:
    """MkDocs event: replace the markers of the page that carries them."""
    if COMMANDS_MARK in markdown:
        markdown = markdown.replace(COMMANDS_MARK, commands_markdown())
    if KEYS_MARK in markdown:
        markdown = markdown.replace(KEYS_MARK, keys_markdown())
    return markdown
