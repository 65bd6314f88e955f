"""docs/cli.md carries the reference that the docs build generates (every command and every
scenario key), committed between its markers so that the page reads whole in the repository:
the committed text is what docs/hooks/reference.py generates now."""

from __future__ import annotations

import importlib.util
import types

from helpers_commands import REPO

HOOK = REPO / "docs" / "hooks" / "reference.py"
PAGE = REPO / "docs" / "cli.md"


def _hook() -> types.ModuleType:
    spec = importlib.util.spec_from_file_location("braidsim_docs_reference_hook", HOOK)
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_the_committed_reference_is_up_to_date() -> None:
    hook = _hook()
    text = PAGE.read_text(encoding="utf-8")
    assert hook.fill(text) == text, (
        "docs/cli.md: the generated reference between its markers is out of date (the "
        "command line or the scenario schema changed); write it again with "
        "`python docs/hooks/reference.py` and commit it"
    )


def test_the_page_holds_every_command_and_key_between_its_markers() -> None:
    from braidsim.params import SCHEMA

    hook = _hook()
    text = PAGE.read_text(encoding="utf-8")
    for mark in (hook.COMMANDS_MARK, hook.KEYS_MARK):
        start, end = text.index(mark), text.index(mark.replace("<!-- ", "<!-- /"))
        assert end - start > 1000, mark  # a region, not a bare placeholder
    for name in ("run", "sweep", "analyze", "lyapunov", "paper"):
        assert f"### braidsim {name}\n" in text
    for key in SCHEMA:
        assert f"| `{key}` |" in text


def test_fill_generates_a_region_again_and_a_bare_marker_whole() -> None:
    hook = _hook()
    page = f"intro\n\n{hook.KEYS_MARK}\n\nstale text\n\n<!-- /braidsim:keys -->\n\nafter\n"
    filled = hook.fill(page)
    assert "stale text" not in filled and filled.endswith("<!-- /braidsim:keys -->\n\nafter\n")
    assert "| `track.clearance` |" in filled and hook.fill(filled) == filled
    # a page with the start marker only (as before the regions were committed)
    assert hook.fill(f"intro\n\n{hook.KEYS_MARK}\n\nafter\n") == filled
