"""The ``haptic-anfis`` command: one entry point, one sub-command per module in
:mod:`haptic_anfis.commands`.

A sub-command module defines ``NAME`` (the word typed after ``haptic-anfis``), ``HELP`` (one line),
``add_arguments(parser)`` and ``run(args) -> int``. Modules are discovered, so adding a sub-command
touches no other file.
"""
from __future__ import annotations

import argparse
import importlib
import pkgutil
import sys

from . import __version__, commands
from .errors import HapticAnfisError

__all__ = ['build_parser', 'main', 'EXIT_ERROR']

#: exit status of a command that failed on bad input or a failed operation (the package's
#: HapticAnfisError, or a ValueError / OSError): one line on standard error, no traceback.
#: (argparse's own usage errors exit with 2.)
EXIT_ERROR = 1


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog='haptic-anfis',
        description='ANFIS soft-tissue force rendering for a breast-palpation haptic simulator.')
    parser.add_argument('--version', action='version', version=f'%(prog)s {__version__}')
    sub = parser.add_subparsers(dest='command', metavar='COMMAND')
    mods = [importlib.import_module(f'{commands.__name__}.{m.name}')
            for m in pkgutil.iter_modules(commands.__path__) if not m.name.startswith('_')]
    for mod in sorted(mods, key=lambda m: m.NAME):
        p = sub.add_parser(mod.NAME, help=mod.HELP, description=mod.HELP)
        mod.add_arguments(p)
        p.set_defaults(_run=mod.run)
    return parser


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    args._program = argv is None  # the program's own command line (not a call from Python)
    if args._program:  # this process and the nodes it starts: DDS over UDP only
        from .nodes.middleware import use_loop_transport
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
