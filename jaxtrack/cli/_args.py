"""Argument checks for the command line: run before any computation, one-line errors, status 2.

The ``type=`` functions reject malformed numbers while parsing; :func:`check_out_dir` finds an
unwritable output folder before a run that might take hours, not after it.
"""

from __future__ import annotations

import argparse
import math
import os
import re
import sys
import tempfile
from pathlib import Path


# reStructuredText inline markup, as the docstrings that some help texts come from write it:
# a role (``:func:`~a.b.c` ``, ``:class:`x` ``), a literal (````x````) or interpreted text (```x```).
_ROLE = re.compile(r":[a-zA-Z_]+(?::[a-zA-Z_]+)?:`(~?)([^`]*)`")
_LITERAL = re.compile(r"``([^`]*)``")
_INTERPRETED = re.compile(r"`([^`]*)`")


def plain_text(text: str) -> str:
    """``text`` without reStructuredText inline markup: what a terminal should show.

    ``:func:`~jaxtrack.learning.fit` `` becomes ``fit`` (the ``~`` form shows the last name, as
    Sphinx does), ``:func:`jaxtrack.learning.fit` `` the full name, ````x```` and ```x``` become
    ``x``. Any backtick left over (unbalanced markup) is dropped.
    """

    def role(match: re.Match) -> str:
        tilde, target = match.groups()
        # A role with an explicit title (`title <target>`) shows the title.
        target = re.sub(r"\s*<[^>]*>$", "", target)
        return target.rsplit(".", 1)[-1] if tilde else target

    text = _ROLE.sub(role, text)
    text = _LITERAL.sub(r"\1", text)
    text = _INTERPRETED.sub(r"\1", text)
    return text.replace("`", "")


class OneLineParser(argparse.ArgumentParser):
    """An ``ArgumentParser`` whose errors are one line on stderr (no usage block), status 2.

    Its help is plain text: descriptions and argument help may come from docstrings, so the
    reStructuredText markup is stripped here, in the one place every ``--help`` is formatted
    (subcommand parsers are made by ``add_subparsers`` with the parent's class, so they share it).
    """

    def error(self, message: str):  # noqa: D102 - argparse API
        raise ArgumentError(f"{self.prog}: error: {message} (see {self.prog} --help)")

    def format_help(self) -> str:  # noqa: D102 - argparse API
        return plain_text(super().format_help())


class ArgumentError(Exception):
    """A bad command-line argument; the message is the whole line printed."""


def int_in(lo: int | None = None, hi: int | None = None):
    """An argparse ``type``: a decimal int with ``lo ≤ value ≤ hi`` (either bound optional)."""

    def parse(text: str) -> int:
        try:
            value = int(text, 10)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected an integer, got {text!r}") from None
        if (lo is not None and value < lo) or (hi is not None and value > hi):
            rng = f"≥ {lo}" if hi is None else (f"≤ {hi}" if lo is None else f"in [{lo}, {hi}]")
            raise argparse.ArgumentTypeError(f"must be {rng}, got {text}")
        return value

    parse.__name__ = "int"  # argparse names the type in its messages
    return parse


def positive_float(text: str) -> float:
    """An argparse ``type``: a finite float > 0."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number, got {text!r}") from None
    if not (math.isfinite(value) and value > 0):
        raise argparse.ArgumentTypeError(f"must be a finite number > 0, got {text}")
    return value


def check_out_dir(path: str) -> str | None:
    """``None`` if files can be written under ``path`` (created later if missing), else why not.

    Creates nothing that stays: an existing folder is tested by creating and deleting a temporary
    file in it; a missing one by the same test on its nearest existing ancestor, which must be a
    folder (a path under a regular file can never be created).
    """
    p = Path(path).expanduser().absolute()
    probe = p
    while not probe.exists():
        if probe.parent == probe:
            return f"--out {path}: no existing parent folder"
        probe = probe.parent
    if not probe.is_dir():
        return f"--out {path}: {probe} is not a folder"
    try:
        with tempfile.TemporaryFile(dir=probe):
            pass
    except OSError as exc:
        return f"--out {path}: cannot write in {probe} ({exc.strerror or exc})"
    return None


def seed_limit() -> int:
    """The largest seed ``jax.random.key`` takes without wrapping: 2⁶³−1 under x64, else 2³²−1."""
    from .._config import _OPT_OUT_VALUES

    x64 = os.environ.get("JAXTRACK_ENABLE_X64", "1").strip().lower() not in _OPT_OUT_VALUES
    return 2**63 - 1 if x64 else 2**32 - 1


def fail(prog: str, message: str) -> int:
    """Print ``prog: error: message`` as one line on stderr; return the status 2."""
    print(f"{prog}: error: {message}", file=sys.stderr)
    return 2
