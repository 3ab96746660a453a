"""``haptic-anfis falcon check``: a step-by-step check of a real Novint Falcon (find, firmware,
homing, positions, a gentle spring, zero force), and the force-scale calibration that writes
``counts_per_nm`` to the falcon_driver parameter file. See :mod:`haptic_anfis.device.falcon_check`."""
from __future__ import annotations

import argparse
import sys

import yaml

from ..device.falcon_check import calibrate, geometry_with, run_check, write_counts_per_nm
from ..device.falcon_usb import FalconUSB
from ..resources import config_file

NAME = 'falcon'


def add_arguments(p: argparse.ArgumentParser) -> None:
    sub = p.add_subparsers(dest='falcon_command', metavar='ACTION', required=True)
    a = sub.add_parser('check', help='find, load firmware, home, read positions, render a gentle '
                       'spring, zero force; prints what it saw at each step')
    a.add_argument('--firmware', default='', metavar='PATH',
                   help="the Novint firmware file (nvent_firmware.bin) to load if the device runs "
                        "none ('' = expect it running)")
    a.add_argument('--index', type=int, default=0, help='which Falcon on the bus (default 0)')
    a.add_argument('--serial', default='', help='USB serial number (overrides --index)')
    a.add_argument('--move-seconds', type=float, default=5.0, metavar='S',
                   help='how long to read positions while you move the grip (default 5)')
    a.add_argument('--spring-seconds', type=float, default=5.0, metavar='S',
                   help='how long to render the spring (default 5)')
    a.add_argument('--spring-force', type=float, default=1.0, metavar='N',
                   help='largest spring force towards the centre [N] (default 1)')
    a.add_argument('--counts-per-nm', type=float, default=None, metavar='C',
                   help='motor scale to use (default: the one in --params-file, else 10000)')
    a.add_argument('--calibrate', type=float, default=None, metavar='KG',
                   help='after the check, calibrate the force scale with a known mass of KG kg '
                        'hung on the grip (a spring scale pulling down works too: give the '
                        'reading in kg) and write counts_per_nm to --params-file')
    a.add_argument('--params-file', default=None, metavar='YAML',
                   help='falcon_driver parameter file to read counts_per_nm from and write the '
                        "calibration to (default: the package's config/falcon_driver.yaml)")


def run(args: argparse.Namespace) -> int:
    params_file = args.params_file or str(config_file('falcon_driver.yaml'))
    counts = args.counts_per_nm if args.counts_per_nm is not None else _counts_in(params_file)
    for name, v in (('--move-seconds', args.move_seconds), ('--spring-seconds',
                    args.spring_seconds), ('--spring-force', args.spring_force),
                    ('--counts-per-nm', counts)):
        if not v > 0:
            raise ValueError(f'{name}: expected a number > 0, got {v!r}')
    if args.calibrate is not None and not (args.calibrate > 0 and args.calibrate < 2.0):
        raise ValueError(f'--calibrate: expected a mass in kg between 0 and 2 (the Falcon holds '
                         f'about 0.9 kg), got {args.calibrate!r}')
    if args.spring_force > 3.0:
        raise ValueError(f'--spring-force: a check is gentle: expected at most 3 N, got '
                         f'{args.spring_force!r}')
    dev = FalconUSB(firmware_path=args.firmware, device_index=args.index, serial=args.serial,
                    geometry=geometry_with(counts), guard_thread=True, log=print)
    print(f'Falcon check (motor scale {counts:g} counts per N m, from '
          f'{"--counts-per-nm" if args.counts_per_nm is not None else params_file})')
    if args.calibrate is None:
        return run_check(dev, move_seconds=args.move_seconds, spring_seconds=args.spring_seconds,
                         spring_force=args.spring_force)
    try:
        code = run_check(dev, move_seconds=args.move_seconds,
                         spring_seconds=args.spring_seconds, spring_force=args.spring_force,
                         keep_open=True)
        if code:
            return code
        print(f'7. calibration with {args.calibrate:g} kg')
        c = calibrate(dev, args.calibrate, wait=lambda prompt: input(f'   {prompt} '))
        write_counts_per_nm(params_file, c)
        print(f'   [ok] counts_per_nm: {c:.1f} written to {params_file}')
        return 0
    finally:
        dev.close()  # zero force; safe when the check already closed it


def _counts_in(params_file: str) -> float:
    """counts_per_nm from a falcon_driver parameter file (10000.0 when absent)."""
    try:
        with open(params_file, encoding='utf-8') as f:
            doc = yaml.safe_load(f) or {}
        v = doc.get('falcon_driver', {}).get('ros__parameters', {}).get('counts_per_nm', 10000.0)
    except (OSError, yaml.YAMLError, AttributeError) as exc:
        print(f'note: cannot read counts_per_nm from {params_file} ({exc}); using 10000',
              file=sys.stderr)
        return 10000.0
    return float(v)
