"""The documentation site's structure: mkdocs.yml's nav against docs/, and the options table of docs/hooks.py.

``python -m mkdocs build --strict`` (``.ci/run``) checks links and references; these tests check what a build does
not: that no page of ``docs/`` is left out of the nav, and that the generated options table lists every option of
the command line.  They read files and call the hook's functions; they never build the site.
"""

from __future__ import annotations

import argparse
import html
import importlib.util
import re
from pathlib import Path

from sparsedepth.cli.parser import build_parser
from sparsedepth.complete import main

ROOT = Path(__file__).resolve().parents[1]
DOCS = ROOT / "docs"

#: Markdown files under docs/ that are deliberately not pages of the nav, with the reason.
NOT_IN_NAV: dict[str, str] = {}


def _hooks():
    """docs/hooks.py as a module (it is not part of the package)."""
    spec = importlib.util.spec_from_file_location("docs_hooks", DOCS / "hooks.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def _nav_pages() -> list[str]:
    """Every ``*.md`` path of mkdocs.yml's ``nav`` (relative to docs/), in order."""
    text = (ROOT / "mkdocs.yml").read_text(encoding="utf-8")
    match = re.search(r"^nav:\n((?:[ \t]+.*\n?|\n)*)", text, re.MULTILINE)
    assert match, "mkdocs.yml has no nav"
    return re.findall(r"(?:^|[\s:-])([\w./-]+\.md)\s*$", match.group(1), re.MULTILINE)


def test_every_nav_page_exists():
    pages = _nav_pages()
    assert "index.md" in pages and "guides/command_line.md" in pages
    missing = [page for page in pages if not (DOCS / page).is_file()]
    assert not missing, f"pages in mkdocs.yml's nav without a file under docs/: {missing}"
    assert len(pages) == len(set(pages)), "a page is in the nav twice"


def test_every_docs_page_is_in_nav():
    pages = set(_nav_pages())
    on_disk = {path.relative_to(DOCS).as_posix() for path in DOCS.rglob("*.md")}
    left_out = sorted(on_disk - pages - set(NOT_IN_NAV))
    assert not left_out, f"docs pages missing from mkdocs.yml's nav (add them, or to NOT_IN_NAV with a reason): {left_out}"
    assert all(reason.strip() for reason in NOT_IN_NAV.values())


def test_the_hook_is_registered_and_the_marker_is_on_the_command_line_page():
    hooks = _hooks()
    config = (ROOT / "mkdocs.yml").read_text(encoding="utf-8")
    assert re.search(r"^hooks:\n\s+- docs/hooks\.py$", config, re.MULTILINE)
    page = (DOCS / "guides" / "command_line.md").read_text(encoding="utf-8")
    assert page.count(hooks.OPTIONS_MARKER) == 1
    rendered = hooks.on_page_markdown(page, page=None, config=None, files=None)
    assert hooks.OPTIONS_MARKER not in rendered
    assert "<table>" in rendered


def _help_all_options(capsys) -> list[str]:
    """The option strings ``--help-all`` prints at the start of its lines, read from its text."""
    assert main(["--help-all"]) == 0
    text = capsys.readouterr().out
    body = text.split("\n\n", 1)[1]  # past the usage block
    options = []
    for line in body.splitlines():
        match = re.match(r"^  (-[\w-]+(?:, --[\w-]+)?)", line)
        if match:
            options.extend(match.group(1).split(", "))
    return options


def test_options_table_lists_every_option_of_the_parser(capsys):
    printed = _help_all_options(capsys)
    assert {"--image", "--depth", "--out", "-q", "--quiet", "--help-all"} <= set(printed)
    table = _hooks().options_table()
    cells = re.findall(r"<tr><td><code>([^<]*)</code></td>", table)
    in_table = {name for cell in cells
                for name in re.match(r"-[\w-]+(?:, -[\w-]+)*", html.unescape(cell)).group(0).split(", ")}
    missing = sorted(set(printed) - in_table)
    assert not missing, f"options of --help-all missing from the docs table: {missing}"
    assert len(cells) == len([a for a in build_parser()._actions if a.option_strings])


def test_options_table_carries_each_option_help_and_default():
    table = html.unescape(_hooks().options_table())
    parser = build_parser()
    for action in parser._actions:
        if action.help and action.option_strings:
            assert " ".join(action.help.split()) in table, action.option_strings
    seed_row = next(row for row in table.split("<tr>") if "<code>--seed " in row)
    assert f"<td>{parser.get_default('seed')}</td>" in seed_row


def test_options_table_of_a_hand_made_parser():
    parser = argparse.ArgumentParser(add_help=False)
    group = parser.add_argument_group("output files")
    group.add_argument("-o", "--out", metavar="PATH", help="where <it> goes.")
    group.add_argument("--level", type=int, default=3, choices=[1, 2, 3], help="how much.")
    group.add_argument("--dry-run", action="store_true", help="do nothing.")
    parser.add_argument("input", help="a positional argument is not an option.")
    table = _hooks().options_table(parser)
    assert "### Output files" in table
    rows = re.findall(r"<tr><td>(.*?)</td><td>(.*?)</td><td>(.*?)</td></tr>", table)
    assert rows == [
        ("<code>-o, --out PATH</code>", "", "where &lt;it&gt; goes."),
        ("<code>--level {1,2,3}</code>", "3", "how much."),
        ("<code>--dry-run</code>", "off", "do nothing."),
    ]


def test_markdown_docstring_rewrites_restructuredtext():
    rewrite = _hooks().markdown_docstring
    assert rewrite("See :func:`~sparsedepth.fill_holes`.") == "See `fill_holes`."
    assert rewrite("See :class:`sparsedepth.Weights`.") == "See `sparsedepth.Weights`."
    assert rewrite("See :data:`the table <sparsedepth.SOLVERS>`.") == "See `the table`."
    assert rewrite("Costs :math:`a^2` each.") == "Costs $a^2$ each."
    assert rewrite("Minimises::\n\n    F = 1\n") == "Minimises:\n\n    F = 1\n"
    assert rewrite("Notes\n.. math:: x = 1\n          + y\n\nAfter.\n") == "Notes\n$$\nx = 1\n+ y\n$$\n\nAfter.\n"
    assert rewrite(".. [1] J. E. Dendy, 1982.") == "[1] J. E. Dendy, 1982."
    assert rewrite("plain ``code`` text") == "plain ``code`` text"


def test_the_api_reference_renders_every_public_name():
    import sparsedepth

    directives = set()
    for page in (DOCS / "reference").glob("*.md"):
        directives |= set(re.findall(r"^::: ([\w.]+)\s*$", page.read_text(encoding="utf-8"), re.MULTILINE))
    missing = sorted(name for name in sparsedepth.__all__ if f"sparsedepth.{name}" not in directives)
    assert not missing, f"names of sparsedepth.__all__ without a ::: directive in docs/reference/: {missing}"
