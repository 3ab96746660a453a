"""The README stays short and its command lines stay true to the CLI (issue 28.5).

Every ``haptic-anfis ...`` in the README must name a real sub-command (and sub-sub-command), every
``--option`` after it must be an option of that command, and every sub-command of the parser must
be mentioned. The parser is the one ``haptic-anfis`` runs (:func:`haptic_anfis.cli.build_parser`).
"""
from __future__ import annotations

import argparse
import re
from pathlib import Path

import pytest

from haptic_anfis.cli import build_parser

README = Path(__file__).resolve().parents[2] / 'README.md'
MAX_LINES = 250

#: one command line: ``haptic-anfis`` and what follows up to the end of the code span / cell / line
_COMMAND = re.compile(r'haptic-anfis((?:[ \t]+[^`|\n]*)?)')


def _subcommands(parser: argparse.ArgumentParser) -> dict[str, argparse.ArgumentParser]:
    out: dict[str, argparse.ArgumentParser] = {}
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            out.update(action.choices)
    return out


def _options(parser: argparse.ArgumentParser) -> set[str]:
    return {s for a in parser._actions for s in a.option_strings}


def command_uses(text: str) -> list[tuple[list[str], list[str], str]]:
    """(command path, --options, the line) for every ``haptic-anfis`` command line in ``text``;
    a placeholder in capitals (``haptic-anfis COMMAND``) names no command and is skipped."""
    uses = []
    for line in text.splitlines():
        for m in _COMMAND.finditer(line):
            words = m.group(1).split()
            path: list[str] = []
            for w in words:
                if w.startswith('-') or not re.fullmatch(r'[a-z][a-z0-9_-]*', w):
                    break
                path.append(w)
            if not path and words and words[0].isupper():
                continue
            opts = [w.split('=', 1)[0] for w in words if w.startswith('--')]
            uses.append((path, opts, line.strip()))
    return uses


def check_uses(text: str, parser: argparse.ArgumentParser) -> list[str]:
    """Problems (one line each) of the command lines in ``text`` against ``parser``."""
    problems = []
    for path, opts, line in command_uses(text):
        p = parser
        for i, word in enumerate(path):
            subs = _subcommands(p)
            if not subs:  # a positional argument (a bag path, a dataset), not a command
                break
            if word not in subs:
                problems.append(f'{" ".join(["haptic-anfis"] + path[:i + 1])}: no such command '
                                f'(known: {", ".join(sorted(subs))}) in: {line}')
                p = None
                break
            p = subs[word]
        if p is None or p is parser:
            continue
        unknown = [o for o in opts if o not in _options(p)]
        if unknown:
            problems.append(f'haptic-anfis {" ".join(path)}: unknown option(s) '
                            f'{", ".join(unknown)} in: {line}')
    return problems


@pytest.fixture(scope='module')
def parser():
    return build_parser()


def test_readme_is_short():
    n = len(README.read_text(encoding='utf-8').splitlines())
    assert n <= MAX_LINES, f'README.md has {n} lines, at most {MAX_LINES}: move the rest to docs/'


def test_readme_command_lines_match_the_cli(parser):
    text = README.read_text(encoding='utf-8')
    assert command_uses(text), 'the README shows no haptic-anfis command'
    assert check_uses(text, parser) == []


def test_readme_mentions_every_command(parser):
    text = README.read_text(encoding='utf-8')
    named = {tuple(path[:1]) for path, _, _ in command_uses(text)}
    missing = sorted(c for c in _subcommands(parser) if (c,) not in named)
    assert missing == [], f'sub-commands the README does not mention: {missing}'


def test_the_check_catches_wrong_lines(parser):
    """The checker itself: a wrong command, sub-command or option is reported; a right one not."""
    good = '`haptic-anfis sim --duration 10 --record out/x` and `haptic-anfis bag play BAG --rate 2`'
    assert check_uses(good, parser) == []
    assert check_uses('`haptic-anfis simulate --duration 1`', parser)
    assert check_uses('`haptic-anfis bag replay BAG`', parser)
    assert check_uses('`haptic-anfis sim --no-such-option`', parser)
    assert check_uses('`haptic-anfis exam run --case normal --speeed 0.02`', parser)
    assert command_uses('`haptic-anfis COMMAND`') == []


def test_docs_command_lines_match_the_cli(parser):
    """The hand-written pages of the manual (docs/*.md; the generated ones are made from the
    parser) name only real commands and options too."""
    problems = []
    for page in sorted((README.parent / 'docs').glob('*.md')):
        problems += [f'{page.name}: {p}' for p in check_uses(page.read_text(encoding='utf-8'),
                                                               parser)]
    assert problems == []
