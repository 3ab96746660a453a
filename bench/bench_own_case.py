"""My own case in 30 minutes: the recipe of docs/workflows.md, run and timed step by step.

In a fresh case folder (``--case-dir``, as a user's ``~/.local/share/haptic_anfis/cases``): copy
the default scene, move and resize its lesion, coarsen the loading grid, ``cases list`` (the new
case is seen), ``cases generate`` (FE sweep + model, ``--coarse``), ``exam run --case`` (the
systematic trainee). Each step is a command as a user types it; its wall time is measured. The
page says the machine and its load: on a busy machine the FE sweep takes longer.

    .venv/bin/python bench/bench_own_case.py [--spacing-mm 10] [--workers 2] [--keep DIR]
"""
from __future__ import annotations

import argparse
import json
import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import yaml

sys.path.insert(0, str(Path(__file__).resolve().parent))
from harness import run_with_page  # noqa: E402  (bench/ is sys.path[0])

ROOT = Path(__file__).resolve().parent.parent
NAME = 'my_case'


def make_scene(folder: Path, spacing_mm: float) -> Path:
    """Step 1: the default scene copied into ``folder`` as ``my_case.yaml``, its lesion moved to
    (y, z) = (-12, 10) mm, 12 mm across, 10 mm under the skin, the loading grid ``spacing_mm``."""
    doc = yaml.safe_load((ROOT / 'config' / 'scenes' / 'default.yaml').read_text())
    doc['name'] = NAME
    doc['description'] = 'My case: carcinoma 12 mm, 10 mm deep, upper outer, dense medium breast'
    les = doc['tumours'][0]
    y, z, r = -12.0, 10.0, 6.0
    rx, ry, rz = doc['breast']['radii_mm']
    skin = rx * (1 - (y / ry) ** 2 - (z / rz) ** 2) ** 0.5
    les.update(name='idc', centre_mm=[round(skin - 10.0, 2), y, z], radius_mm=r)
    doc['loading']['spacing_mm'] = spacing_mm
    path = folder / f'{NAME}.yaml'
    path.write_text(yaml.safe_dump(doc, sort_keys=False))
    return path


def timed(cmd: list[str], env: dict, log: Path) -> tuple[float, str]:
    """Run ``haptic-anfis CMD``; (wall time [s], its output's last lines). Raises on failure."""
    t0 = time.monotonic()
    with open(log, 'a') as f:
        f.write(f'\n$ haptic-anfis {" ".join(cmd)}\n')
        f.flush()
        p = subprocess.run([sys.executable, '-m', 'haptic_anfis.cli', *cmd], env=env, cwd=ROOT,
                           stdout=subprocess.PIPE, stderr=f, text=True)
        f.write(p.stdout)
    if p.returncode != 0:
        raise SystemExit(f'haptic-anfis {" ".join(cmd)}: exit code {p.returncode} (see {log})')
    return time.monotonic() - t0, p.stdout


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument('--spacing-mm', type=float, default=10.0,
                    help='loading grid spacing of the new case [mm] (the default scene: 6)')
    ap.add_argument('--workers', type=int, default=2, help='FE worker processes')
    ap.add_argument('--keep', type=Path, default=None, help='case folder to keep (default: a '
                    'temporary one)')
    a = ap.parse_args()
    folder = a.keep or Path(tempfile.mkdtemp(prefix='own-case-'))
    folder.mkdir(parents=True, exist_ok=True)
    log = folder / 'recipe.log'
    env = dict(os.environ, HAPTIC_ANFIS_CASE_DIR=str(folder))
    t_all = time.monotonic()
    rows = []
    t0 = time.monotonic()
    make_scene(folder, a.spacing_mm)
    rows.append(('copy the default scene, edit the lesion and the grid', f'{NAME}.yaml',
                 time.monotonic() - t0))
    dt, out = timed(['cases', 'list'], env, log)
    seen = any(line.startswith(NAME + '*') for line in out.splitlines())
    rows.append(('the new case is listed' + ('' if seen else ' (NOT SEEN)'), 'cases list', dt))
    dt, out = timed(['cases', 'generate', NAME, '--coarse', '--workers', str(a.workers),
                     '--quiet', '--work-root', str(folder / 'work')], env, log)
    rows.append(('FE sweep, surface mesh, model', f'cases generate {NAME} --coarse '
                 f'--workers {a.workers}', dt))
    samples = next((ln.strip() for ln in out.splitlines() if 'samples' in ln), '')
    dt, out = timed(['exam', 'run', '--case', NAME, '--json'], env, log)
    rep = json.loads(out.strip().splitlines()[-1])
    rows.append(('an exam on it (the systematic trainee)', f'exam run --case {NAME}', dt))
    total = time.monotonic() - t_all
    print(f'Loading grid {a.spacing_mm:g} mm (the default scene: 6 mm), coarse mesh, '
          f'{a.workers} FE workers; all commands niced as the caller is '
          f'(nice {os.nice(0)}).\n')
    print('| step | command | wall time |\n|---|---|---|')
    for what, cmd, dt in rows:
        print(f'| {what} | `{cmd}` | {dt / 60:.1f} min ({dt:.0f} s) |')
    print(f'| **all** | | **{total / 60:.1f} min** |\n')
    print(f'generate: {samples}')
    les = rep['lesions'][0]
    print(f"exam: score {rep['score']:.0f} ({rep['verdict']}), deep coverage "
          f"{rep['coverage_pct']['deep']:.0f} %, lesion {les['name']} "
          f"{'found' if les['found'] else les['missed']}")
    if a.keep is None:
        shutil.rmtree(folder, ignore_errors=True)
    return 0


if __name__ == '__main__':
    sys.exit(run_with_page(main, __file__, __doc__))
