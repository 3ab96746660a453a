"""The ``haptic-anfis`` command: one entry point, one sub-command per module in
:mod:`haptic_anfis.commands`, listed with its one-line help in
:data:`haptic_anfis.commands.COMMANDS`.

A sub-command module defines ``NAME`` (the word typed after ``haptic-anfis``),
``add_arguments(parser)`` and ``run(args) -> int``, and imports what it needs at its top. Only the
command typed is imported, so ``haptic-anfis --help`` and a light command do not load ROS, numba
or the FE stack.
"""
from __future__ import annotations

import argparse
import importlib
import sys
from collections.abc import Sequence
from types import ModuleType

from . import __version__
from .commands import COMMANDS
from .errors import HapticAnfisError
from .nodes.middleware import use_loop_transport

__all__ = ['build_parser', 'command_module', 'main', 'EXIT_ERROR']

#: exit status of a command that failed on bad input or a failed operation (the package's
#: HapticAnfisError, or a ValueError / OSError): one line on standard error, no traceback.
#: (argparse's own usage errors exit with 2.)
EXIT_ERROR = 1


def command_module(word: str) -> ModuleType:
    """The module of the sub-command ``word`` (a key of :data:`COMMANDS`), imported."""
    return importlib.import_module(f'{__package__}.commands.{word}')


def build_parser(only: str | None = None) -> argparse.ArgumentParser:
    """The parser of ``haptic-anfis``. Every command is listed with its help; the arguments of
    every command are added when ``only`` is None, else those of the command ``only`` alone (an
    unknown word or '' adds none), so only that command's module is imported."""
    parser = argparse.ArgumentParser(
        prog='haptic-anfis',
        description='ANFIS soft-tissue force rendering for a breast-palpation haptic simulator.')
    parser.add_argument('--version', action='version', version=f'%(prog)s {__version__}')
    sub = parser.add_subparsers(dest='command', metavar='COMMAND')
    for word, text in COMMANDS.items():
        p = sub.add_parser(word, help=text, description=text)
        if only is None or only == word:
            mod = command_module(word)
            mod.add_arguments(p)
            p.set_defaults(_run=mod.run)
    return parser


def _command_word(argv: Sequence[str]) -> str:
    """The sub-command of a command line: its first word that is not an option ('' if none;
    ``haptic-anfis`` itself takes no option with a value)."""
    return next((a for a in argv if not a.startswith('-')), '')


def main(argv: list[str] | None = None) -> int:
    word = _command_word(sys.argv[1:] if argv is None else argv)
    try:
        parser = build_parser(only=word)
    except ModuleNotFoundError as exc:  # an optional dependency of that command (setup.py extras)
        if (exc.name or '').startswith(__package__):
            raise
        print(f'haptic-anfis {word}: error: {exc} (an optional dependency: see the package '
              "extras, e.g. pip install 'haptic_anfis[ros]')", file=sys.stderr)
        return EXIT_ERROR
    args = parser.parse_args(argv)
    args._program = argv is None  # the program's own command line (not a call from Python)
    if args._program:  # this process and the nodes it starts: DDS over UDP only
        use_loop_transport()
    if not getattr(args, '_run', None):
        parser.print_help()
        return 2
    try:
        return int(args._run(args) or 0)
    except KeyboardInterrupt:
        print('interrupted', file=sys.stderr)
        return 130
    except (HapticAnfisError, ValueError, OSError) as exc:  # bad input: say what, no traceback
        # one line per problem (a parameter check lists each bad file line / parameter)
        for line in str(exc).splitlines() or [type(exc).__name__]:
            print(f'haptic-anfis {args.command}: error: {line}', file=sys.stderr)
        return EXIT_ERROR


if __name__ == '__main__':
    sys.exit(main())
