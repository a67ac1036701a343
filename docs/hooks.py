"""Build-time helpers of the documentation site: the command line's options table and Markdown docstrings.

``docs/guides/command_line.md`` holds the marker :data:`OPTIONS_MARKER`; the MkDocs hook :func:`on_page_markdown`
replaces it by :func:`options_table`, one HTML table per argument group of
:func:`sparsedepth.cli.parser.build_parser` (option and value, default, help), so the table always lists the
options of the installed version.  :class:`SphinxRoles`, a griffe extension, passes every docstring of the API
reference through :func:`markdown_docstring`.  Both are registered in ``mkdocs.yml`` (``hooks`` and the python
handler's ``extensions``); ``tests/test_docs_site.py`` imports this file by path.
"""

from __future__ import annotations

import argparse
import html
import re

try:  # the docs extra; the options table below needs only the standard library
    from griffe import Extension as _GriffeExtension
except ImportError:  # pragma: no cover - without mkdocstrings installed
    _GriffeExtension = object

OPTIONS_MARKER = "<!-- options-table -->"

_ROLE = re.compile(r":(?:py:)?(?:func|class|meth|attr|data|mod|obj|exc|const|ref|term):`(~?)([^`<]*?)(?:\s*<([^`>]*)>)?`")
_MATH_ROLE = re.compile(r":math:`([^`]*)`")
_MATH_BLOCK = re.compile(r"^(?P<indent>[ \t]*)\.\. math::[ \t]*(?P<first>.*)\n(?P<body>(?:(?P=indent)[ \t]+.*\n|[ \t]*\n)*)",
                         re.MULTILINE)
_CITATION = re.compile(r"^(?P<indent>[ \t]*)\.\. (\[[^\]]+\])", re.MULTILINE)
_LITERAL_MARKER = re.compile(r"(?<=\S)::$", re.MULTILINE)


def _option_names(action: argparse.Action) -> str:
    """``-q, --quiet`` with the metavar or the choices of the option's value."""
    names = ", ".join(action.option_strings)
    if action.nargs == 0:
        return names
    if action.metavar is not None:
        value = action.metavar
    elif action.choices is not None:
        value = "{" + ",".join(str(c) for c in action.choices) + "}"
    else:
        value = action.dest.upper()
    return f"{names} {value}"


def _default(action: argparse.Action) -> str:
    """The default argparse stores, or an empty cell when the option has none of its own."""
    default = action.default
    if default is None or default is argparse.SUPPRESS:
        return ""
    if action.nargs == 0 and default is False:
        return "off"
    if action.nargs == 0 and default is True:
        return "on"
    return str(default)


def _cell(text: str) -> str:
    """One table cell: the text on one line (runs of white space made one space), HTML-escaped."""
    return html.escape(" ".join(text.split()), quote=False)


def option_rows(parser: argparse.ArgumentParser) -> list[tuple[str, str, str, str, str]]:
    """Every option of ``parser``: ``(group title, option and value, default, help, dest)``, in the parser's order."""
    rows = []
    for group in parser._action_groups:  # argparse keeps its groups only here
        for action in group._group_actions:
            if not action.option_strings:
                continue
            rows.append((group.title or "", _option_names(action), _default(action), action.help or "",
                         action.dest))
    return rows


def options_table(parser: argparse.ArgumentParser | None = None) -> str:
    """The options of ``parser`` (default: the command line's) as one HTML table per argument group."""
    if parser is None:
        from sparsedepth.cli.parser import build_parser

        parser = build_parser()
    parts = []
    title = None
    for group, names, default, help_text, _ in option_rows(parser):
        if group != title:
            if title is not None:
                parts.append("</tbody></table>\n")
            title = group
            parts.append(f"\n### {html.escape(group[:1].upper() + group[1:], quote=False)}\n\n")
            parts.append("<table><thead><tr><th>option</th><th>default</th><th>what it does</th></tr></thead>"
                         "<tbody>\n")
        parts.append(f"<tr><td><code>{_cell(names)}</code></td><td>{_cell(default)}</td>"
                     f"<td>{_cell(help_text)}</td></tr>\n")
    if title is not None:
        parts.append("</tbody></table>\n")
    return "".join(parts)


def _role_text(match: re.Match) -> str:
    """Inline code for a Sphinx cross-reference role: the last name with ``~``, the whole path without."""
    tilde, target, explicit = match.groups()
    if explicit is not None:
        return f"`{target.strip() or explicit}`"
    return f"`{target.rsplit('.', 1)[-1] if tilde else target}`"


def _math_block(match: re.Match) -> str:
    """A ``.. math::`` directive as a ``$$`` block of the arithmatex extension."""
    indent = match.group("indent")
    lines = [match.group("first").strip()] + [line.strip() for line in match.group("body").splitlines()]
    formula = "\n".join(f"{indent}{line}" for line in lines if line)
    return f"{indent}$$\n{formula}\n{indent}$$\n\n"


def markdown_docstring(text: str) -> str:
    """The reStructuredText of a numpydoc docstring that Markdown does not read, written as Markdown.

    Cross-reference roles (``:func:`~sparsedepth.fill_holes```) become inline code, ``:math:`` roles and ``..
    math::`` blocks become arithmatex maths, ``.. [1]`` citations lose their directive dots, and a paragraph's
    closing ``::`` (a literal block follows, which Markdown shows as code by its indent) becomes ``:``.
    """
    text = _MATH_BLOCK.sub(_math_block, text)
    text = _MATH_ROLE.sub(lambda m: f"${m.group(1)}$", text)
    text = _ROLE.sub(_role_text, text)
    text = _CITATION.sub(lambda m: f"{m.group('indent')}{m.group(2)}", text)
    return _LITERAL_MARKER.sub(":", text)


class SphinxRoles(_GriffeExtension):
    """Griffe extension of the API reference: every docstring through :func:`markdown_docstring`.

    Registered in ``mkdocs.yml`` as ``docs/hooks.py:SphinxRoles`` among the python handler's ``extensions``.
    """

    def on_instance(self, *, obj, **kwargs) -> None:  # noqa: ARG002 - the griffe hook signature
        """Rewrite the docstring of ``obj`` when griffe creates it."""
        if obj.docstring is not None:
            obj.docstring.value = markdown_docstring(obj.docstring.value)


def on_page_markdown(markdown, page, config, files):  # noqa: ARG001 - the MkDocs hook signature
    """Replace :data:`OPTIONS_MARKER` in a page by :func:`options_table`."""
    if OPTIONS_MARKER in markdown:
        markdown = markdown.replace(OPTIONS_MARKER, options_table())
    return markdown
