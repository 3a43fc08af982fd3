"""`jaxtrack --help` and every subcommand's `--help` are plain text: no reStructuredText markup.

Help texts partly come from docstrings (the top-level description is the CLI module's first
docstring line), which write ``x`` and :func:`x`; a terminal should show neither.
"""

import argparse
import re

import pytest

from jaxtrack.cli import _parser, main
from jaxtrack.cli._args import plain_text

# A role such as :func: or :py:class: (lower-case, so HOST:PORT-style metavars do not match).
_ROLE = re.compile(r":[a-z_]+(?::[a-z_]+)?:")


def _subcommands() -> list[str]:
    actions = [a for a in _parser()._actions if isinstance(a, argparse._SubParsersAction)]
    assert actions, "the jaxtrack parser has no subcommands"
    return sorted(actions[0].choices)


def test_every_subcommand_is_covered():
    # The parametrisation below reads the parser; this pins that it found the known commands.
    assert {"demo", "design", "reproduce"} <= set(_subcommands())


@pytest.mark.parametrize("argv", [[]] + [[name] for name in _subcommands()], ids=lambda a: " ".join(a) or "jaxtrack")
def test_help_has_no_rst_markup(argv, capsys):
    assert main([*argv, "--help"]) == 0
    text = capsys.readouterr().out
    assert "usage: jaxtrack" in text
    assert "`" not in text, text
    assert not _ROLE.search(text), text


def test_plain_text_strips_roles_literals_and_interpreted_text():
    assert plain_text("The ``jaxtrack`` command") == "The jaxtrack command"
    assert plain_text("see :func:`~jaxtrack.learning.fit` and :class:`jaxtrack.InputError`") == (
        "see fit and jaxtrack.InputError"
    )
    assert plain_text(":py:meth:`the fit <jaxtrack.learning.fit>`, `x`") == "the fit, x"
    assert plain_text("HOST:PORT, τ = 1 s") == "HOST:PORT, τ = 1 s"
