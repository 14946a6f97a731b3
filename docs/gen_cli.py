"""The command-line reference, written from the ``bayesplate`` parser itself.

A MkDocs hook (``hooks:`` in ``mkdocs.yml``): on the page ``cli.md`` the line
``<!-- cli-reference -->`` is replaced by one section per subcommand, walked from
:func:`bayesplate.cli.build_parser` (usage, description, every argument with its help,
choices and default), so the reference is made at every build and never goes stale.

Run as a script it prints the same Markdown: ``python docs/gen_cli.py > cli.md``.
"""

from __future__ import annotations

import argparse
import re

PLACEHOLDER = "<!-- cli-reference -->"
PAGE = "cli.md"
WIDTH = 88  # usage lines wrap here, whatever the terminal that builds the site

# Markdown characters that would start emphasis or a link in argparse's plain help text.
_ESCAPE = re.compile(r"([\\*_\[\]<>])")


def _text(text):
    """Plain help text as Markdown: spans in backticks kept, the rest escaped."""
    parts = re.split(r"(`[^`]*`)", " ".join(text.split()))
    return "".join(p if p.startswith("`") else _ESCAPE.sub(r"\\\1", p) for p in parts)


def _subparsers(parser):
    """The subparsers action of ``parser`` (None when it has none)."""
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            return action
    return None


def _usage(parser):
    """The usage of ``parser`` without its "usage: " prefix, wrapped at a fixed width."""
    formatter = argparse.HelpFormatter(prog=parser.prog, width=WIDTH)
    formatter.add_usage(parser.usage, parser._actions, parser._mutually_exclusive_groups, "")
    return formatter.format_help().strip("\n")


def _invocation(action, formatter):
    """How an argument is written: ``-o DIR, --output DIR`` or ``case``."""
    return formatter._format_action_invocation(action)


def _argument(action, formatter):
    """One argument as a Markdown list item."""
    line = f"- `{_invocation(action, formatter)}`"
    help_text = formatter._expand_help(action) if action.help else ""
    if help_text:
        line += f": {_text(help_text)}"
    if action.required and action.option_strings:
        line += " (required)"
    return line


def _command(name, parser, summary):
    """The Markdown section of one subcommand."""
    formatter = parser._get_formatter()
    lines = [f"## `bayesplate {name}`", ""]
    if summary:
        lines += [_text(summary[:1].upper() + summary[1:]) + ".", ""]
    lines += ["```text", _usage(parser), "```", ""]
    if parser.description:
        lines += [_text(parser.description), ""]
    for group in parser._action_groups:
        actions = [a for a in group._group_actions if a.help is not argparse.SUPPRESS]
        actions = [a for a in actions if not isinstance(a, argparse._HelpAction)]
        if not actions:
            continue
        title = (group.title or "arguments").replace("optional arguments", "options")
        lines += [f"**{title[:1].upper() + title[1:]}**", ""]
        if group.description:
            lines += [_text(group.description), ""]
        lines += [_argument(a, formatter) for a in actions] + [""]
    return lines


def cli_reference():
    """The whole reference as Markdown: the top-level options, then each subcommand."""
    from bayesplate.cli import build_parser

    parser = build_parser()
    formatter = parser._get_formatter()
    lines = [
        "```text",
        _usage(parser),
        "```",
        "",
        _text(parser.description or ""),
        "",
    ]
    top = [
        a for a in parser._actions if a.option_strings and not isinstance(a, argparse._HelpAction)
    ]
    if top:
        lines += ["**Options of every command**", ""]
        lines += [_argument(a, formatter) for a in top] + [""]
    sub = _subparsers(parser)
    summaries = {a.dest: a.help for a in sub._choices_actions}
    lines += ["| command | what it does |", "|---|---|"]
    lines += [f"| [`{n}`](#bayesplate-{n}) | {_text(summaries.get(n, ''))} |" for n in sub.choices]
    lines += [""]
    for name, subparser in sub.choices.items():
        lines += _command(name, subparser, summaries.get(name))
    return "\n".join(lines)


def on_page_markdown(markdown, page, **kwargs):
    """MkDocs hook: fill the placeholder of ``cli.md`` with the reference."""
    if page.file.src_uri == PAGE:
        if PLACEHOLDER not in markdown:
            raise ValueError(f"{PAGE} has lost its placeholder {PLACEHOLDER}")
        return markdown.replace(PLACEHOLDER, cli_reference())
    return markdown


if __name__ == "__main__":
    print(cli_reference())
