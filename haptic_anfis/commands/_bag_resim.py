"""``haptic-anfis bag resim``: the recorded poses through the current contact tracker and force
model, compared with the recorded force commands (no ROS; see :mod:`haptic_anfis.commands.bag`)."""
from __future__ import annotations

import argparse
import sys

from ..nodes.parameters import ParameterError
from ..nodes.resim import resimulate


def resim(args: argparse.Namespace) -> int:
    try:
        r = resimulate(args.path, params_files=args.params_file,
                       force_overrides={'model_path': args.model} if args.model else None)
    except ParameterError as exc:
        raise ValueError(str(exc)) from None
    print(r.format())
    if args.tolerance is not None and r.max_diff_N > args.tolerance:
        print(f'max force difference {r.max_diff_N:.3g} N exceeds --tolerance {args.tolerance:g} N',
              file=sys.stderr)
        return 1
    return 0
