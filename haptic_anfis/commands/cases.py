"""``haptic-anfis cases``: the palpation case library.

    haptic-anfis cases list [--json] [--no-timing]
    haptic-anfis cases sweep [NAMES...] [--workers N] [--dask local|ADDRESS] [--status] [--coarse]
    haptic-anfis cases generate [NAMES...] [--workers N] [--coarse] [--dask local|ADDRESS]
                                [--no-train | --train-only] [--config config/force_model.yaml]
    haptic-anfis cases regrade [NAMES...] [--threshold PCT]

Graded cases (scenes with lesion rings in their loading: every case but ``default``) are solved
per point into the committed store ``fe_store/`` (resumable across sessions) and shipped only
when complete and passing the gates (haptic_anfis.cases.build). A scene without rings (a user's
own) keeps the work-dir sweep of :mod:`haptic_anfis.cases.generate`.
"""
from __future__ import annotations

import argparse
import json
import sys
import textwrap
import time
from pathlib import Path

from ..cases import CaseError, CaseLibrary, library, user_case_dir
from ..cases.build import build_case, regrade_case
from ..cases.generate import generate_case
from ..cases.library import add_case_dir_argument, use_case_dir
from ..cases.summary import case_summary, format_markdown, format_table
from ..cases.sweeps import case_stores, store_status, sweep_case_store
from ..exam.config import load_exam_config
from ..optional import optional
from ..tissue.dataset import DATA_DIR
from ..tissue.scene import SCENE_DIR
from ..tissue.sweep import limit_threads
from .threshold import percentage
from .train import load_config

distributed = optional('distributed')  # --dask: FE points on a dask cluster (the 'dask' extra)

NAME = 'cases'


def add_arguments(p: argparse.ArgumentParser) -> None:
    sub = p.add_subparsers(dest='action', metavar='ACTION')
    ls = sub.add_parser('list', help='one row per case: level, lumps, ready, description (--wide: '
                        'lesions, size, data, model, errors, speed)')
    ls.add_argument('--wide', action='store_true',
                    help='the wide table (lesions, breast, FE rows, model structure, errors, '
                         'evaluation time; about 190 columns)')
    ls.add_argument('--json', action='store_true', help='a JSON list of objects instead')
    ls.add_argument('--markdown', action='store_true',
                    help="the README's table (rules and lesion contrast per case) instead")
    ls.add_argument('--no-timing', action='store_true', help='skip the evaluation-time measurement')
    ls.add_argument('--threshold', type=percentage, default=None, metavar='PCT',
                    help="grade the lesions at this palpability threshold [%%] (a trainee's own, "
                         '`haptic-anfis threshold`) instead of the stored grading')
    add_case_dir_argument(ls)
    rg = sub.add_parser('regrade', help="grade shipped cases again from their FE store (the "
                        "dataset sidecar's grading; the models stay)")
    rg.add_argument('names', nargs='*', help='cases (default: every shipped graded case)')
    rg.add_argument('--threshold', type=percentage, default=None, metavar='PCT',
                    help="palpability threshold [%%] (default: config/exam.yaml's palpable_pct)")
    rg.add_argument('--store', type=Path, default=None,
                    help='per-point store root (default fe_store/ in the source tree)')
    add_case_dir_argument(rg)
    sw = sub.add_parser('sweep', help='solve the missing FE points of cases into the committed '
                        'per-point store (fe_store/; resumable, parallel, local or dask)')
    sw.add_argument('names', nargs='*', help='cases (default: every graded case, i.e. every '
                    'scene with lesion rings in its loading, the most advanced first)')
    sw.add_argument('--workers', type=int, default=2,
                    help='local FE worker processes, one math thread each (default 2)')
    sw.add_argument('--dask', metavar='local|ADDRESS', default=None,
                    help="a dask.distributed scheduler's address (or 'local')")
    sw.add_argument('--coarse', action='store_true', help='the coarse mesh (CI / quick looks)')
    sw.add_argument('--store', type=Path, default=None,
                    help='per-point store root (default fe_store/ in the source tree)')
    sw.add_argument('--retry-failed', action='store_true',
                    help='solve again the points recorded as failed')
    sw.add_argument('--status', action='store_true', help='only print solved / missing per case')
    sw.add_argument('--quiet', action='store_true', help='no progress bar')
    _library_arguments(sw)
    gen = sub.add_parser('generate', help='FE sweep (resumable, parallel) then train, per case')
    gen.add_argument('names', nargs='*', help='cases to generate (default: every case but '
                     '"default", whose files come with the package)')
    gen.add_argument('--workers', type=int, default=2,
                     help='FE worker processes, one math thread each (default 2)')
    gen.add_argument('--coarse', action='store_true',
                     help="the scenes' coarse mesh density (4 cells across the probe)")
    gen.add_argument('--dask', metavar='local|ADDRESS', default=None,
                     help="run the FE points on a dask.distributed cluster: 'local' starts a "
                          'LocalCluster of --workers single-threaded processes; else the '
                          "scheduler's address (needs `pip install distributed`)")
    mode = gen.add_mutually_exclusive_group()
    mode.add_argument('--no-train', action='store_true', help='FE sweep and mesh only')
    mode.add_argument('--train-only', action='store_true',
                      help='train on the existing datasets (no FE)')
    gen.add_argument('--config', default=None,
                     help='force-model hyper-parameters (default config/case_model.yaml)')
    gen.add_argument('--work-root', type=Path, default=None,
                     help='per-case FE work directories for resuming (default .fe_work/cases)')
    gen.add_argument('--quiet', action='store_true', help='no progress line')
    gen.add_argument('--store', type=Path, default=None,
                     help='per-point FE store of the graded cases (default fe_store/ in the '
                          'source tree)')
    _library_arguments(gen)


def _library_arguments(p: argparse.ArgumentParser) -> None:
    add_case_dir_argument(p)
    p.add_argument('--scene-dir', type=Path, default=None,
                   help='scene files of another library (default config/scenes)')
    p.add_argument('--data-dir', type=Path, default=None,
                   help="that library's data directory (default the package's)")


def _open_library(args: argparse.Namespace, **kw):

    # the package's cases and the user's own (--case-dir), or another library (--scene-dir)
    return CaseLibrary(args.scene_dir or SCENE_DIR, args.data_dir or DATA_DIR, **kw,
                       user_dir=None if args.scene_dir else user_case_dir())


def run(args: argparse.Namespace) -> int:
    use_case_dir(args.case_dir)   # before anything reads the library; the nodes inherit it
    if args.action == 'list':
        return _list(args)
    if args.action == 'generate':
        return _generate(args)
    if args.action == 'sweep':
        return _sweep(args)
    if args.action == 'regrade':
        return _regrade(args)
    print('haptic-anfis cases: give an action: list, sweep, generate or regrade', file=sys.stderr)
    return 2


#: [columns] the width ``cases list`` fits (a terminal beside an editor)
LIST_WIDTH = 100


def narrow_table(lib, width: int = LIST_WIDTH, threshold_pct: float | None = None) -> str:
    """``cases list``: one line per case within ``width`` columns: name, level, palpable /
    all lesions, ready (model and mesh made from the scene as it is), its description (cut to
    fit), then a line naming the user's own case folder. ``threshold_pct``: the lesions graded
    at this palpability threshold [%] instead of the stored grading."""
    head = f'{"case":<24} {"lvl":>3} {"lumps":>5} {"ready":<5} description'
    lines = [head, '-' * width]
    own = set(lib.user_names())
    for c in lib.cases():
        try:
            g = c.grading(threshold_pct)
            n = len(c.scene.tumours)
            felt = (sum(bool(x.get('palpable')) for x in g.get('lesions', ())) if g is not None
                    else '?')
            ready = 'no' if c.missing(('model_path', 'mesh_path')) else (
                'stale' if c.scene_changed() else 'yes')
            level = c.level_at(threshold_pct)
            lvl = ('bd' if c.below_device_at(threshold_pct) else
                   '-' if level is None else str(level))
            desc = c.description
        except CaseError as exc:   # a broken scene file: said in its row
            n, felt, ready, lvl, desc = 0, '?', 'no', '-', str(exc)
        name = c.name + ('*' if c.name in own else '')
        line = f'{name:<24} {lvl:>3} {f"{felt}/{n}":>5} {ready:<5} {desc}'
        lines.append(line if len(line) <= width else line[:width - 3] + '...')
    notes = ['lvl: difficulty 1-5 from the FE (- not graded; bd: every lesion below what this '
             'device renders, so no level: not drawn by exam run --next, not counted for mastery, '
             'open it by name to show what a stylus cannot give); lumps: palpable / all lesions (? '
             'not graded); ready: stale = scene edited since generated (cases generate NAME); '
             '* your own case; --wide: the lesions, FE and model figures']
    if lib.user is not None:
        notes.append(f'own cases: {lib.user.scene_dir} ({len(own)})'
                     + (f'; not used, a package case has the name: {", ".join(lib.shadowed())}'
                        if lib.shadowed() else ''))
    lines.append('-' * width)
    lines += [w for n in notes for w in textwrap.wrap(n, width)]
    return '\n'.join(lines)


def _list(args: argparse.Namespace) -> int:

    if not (args.wide or args.json or args.markdown):
        print(narrow_table(library(), threshold_pct=args.threshold))
        return 0
    rows = [case_summary(c, timing=not args.no_timing, threshold_pct=args.threshold)
            for c in library().cases()]
    if args.json:
        print(json.dumps(rows, indent=1))
    elif args.markdown:
        print(format_markdown(rows))
    else:
        print(format_table(rows))
    return 0


def _regrade(args: argparse.Namespace) -> int:
    """Grade shipped cases again from their store; one line per case with its level and where
    each lesion is found."""
    lib = library()
    thr = args.threshold if args.threshold is not None else load_exam_config().palpable_pct
    cases = ([lib.get(n) for n in args.names] if args.names else
             [c for c in lib.cases() if c.scene.graded and c.grading() is not None])
    failed = 0
    for c in cases:
        try:
            g = regrade_case(c, store_root=args.store, threshold_pct=thr)
        except CaseError as exc:
            print(f'{c.name}: {exc}', flush=True)
            failed += 1
            continue
        print(regrade_line(c.name, g), flush=True)
    return 1 if failed else 0


def regrade_line(name: str, grading: dict) -> str:
    """One line for a regraded case: its level and where each lesion is found, or why not. A
    nodular case's lesions are told by its background grading (found when it stands out from the
    firmest normal region), a smooth case's by its contrast against the breast without it."""
    bg = grading.get('background')
    if bg is not None:
        entries, found, pct = bg['lesions'], 'stands_out', 'margin_pct'
        over = ' over the firmest normal region'
    else:
        entries, found, pct, over = grading['lesions'], 'palpable', 'contrast_pct', ''
    les = [f'{e["lesion"]} ' + (f'd{e["difficulty"]} at {e["found_level"]} '
                                f'({e["found_depth_m"] * 1e3:g} mm, {e[pct]:+.1f} %{over})'
                                if e[found] else e['reason'])
           for e in entries]
    return f'{name}: level {grading["level"]}: {"; ".join(les) or "no lesion"}'


def _executor(args: argparse.Namespace):
    """(executor or None, closer) for --dask."""
    if not args.dask:
        return None, lambda: None
    if distributed is None:
        raise ValueError('--dask: the dask.distributed package is not installed '
                         '(pip install distributed)')
    if args.dask == 'local':

        limit_threads()  # the workers inherit one math thread each
        cluster = distributed.LocalCluster(n_workers=args.workers, threads_per_worker=1, processes=True,
                               dashboard_address=None)
        client = distributed.Client(cluster)

        def close():
            client.close()
            cluster.close()
    else:
        client = distributed.Client(args.dask)
        close = client.close
    return client, close  # per-point tasks go to the Client itself (taken as they complete)


def _sweep(args: argparse.Namespace) -> int:

    if args.workers < 1:
        raise ValueError(f'--workers must be >= 1, got {args.workers}')
    lib = _open_library(args)
    names = args.names or [n for n in lib.names() if lib.get(n).scene.graded]
    cases = [lib.get(n) for n in names]
    for c in cases:
        _ = c.scene
    if not args.names:  # finish what is started first: a case ships only when complete
        done = {c.name: store_status(case_stores(c, args.store, args.coarse), with_partial=False)
                for c in cases}
        cases.sort(key=lambda c: (-done[c.name].solved / max(done[c.name].total, 1), c.name))
    if args.status:
        for c in cases:
            st = store_status(case_stores(c, args.store, args.coarse), with_cpu=True)
            print(f'{c.name:<28} {st.solved:4d}/{st.total:<4d} solved, {len(st.failed)} failed, '
                  f'{len(st.missing)} missing, {st.cpu_s / 3600:.2f} CPU-h'
                  + (f'; failed: {", ".join(st.failed)}' if st.failed else '')
                  + (f'; partial: {_partial_text(st.partial)}' if st.partial else ''), flush=True)
        return 0
    executor, close = _executor(args)
    t0 = time.time()
    try:
        for k, case in enumerate(cases, 1):
            st = sweep_case_store(case, root=args.store, coarse=args.coarse, executor=executor,
                                  workers=args.workers, progress=not args.quiet,
                                  retry_failed=args.retry_failed)
            print(f'[case {k}/{len(cases)}] {case.name}: {st.solved}/{st.total} points solved'
                  + (f', FAILED: {", ".join(st.failed)}' if st.failed else '')
                  + (f', partial: {_partial_text(st.partial)}' if st.partial else ''), flush=True)
    finally:
        close()
    print(f'{len(cases)} case(s) swept in {time.time() - t0:.0f} s', flush=True)
    return 0


def _partial_text(partial: dict[str, list[float]]) -> str:
    """'y-032000_z+000000 (no 16 mm), ...': the partial points and the depths they lack."""
    return ', '.join(f'{k} (no {"/".join(f"{1e3 * d:g}" for d in v)} mm)'
                     for k, v in partial.items())


def _generate(args: argparse.Namespace) -> int:

    if args.workers < 1:
        raise ValueError(f'--workers must be >= 1, got {args.workers}')
    lib = _open_library(args, work_root=args.work_root)
    names = args.names or [n for n in lib.names() if n != 'default']
    cases = [lib.get(n) for n in names]  # unknown names fail before any work
    for c in cases:
        _ = c.scene  # and invalid scenes
        if args.train_only and not c.scene.graded and not c.dataset_path.is_file():
            raise CaseError(f'case {c.name!r}: no dataset {str(c.dataset_path)!r} to train on '
                            '(--train-only runs no FE; run without it to sweep the FE first)')
    config = args.config
    if config is None:  # config/case_model.yaml beside the scene files (source tree or share)
        config = str(SCENE_DIR.parent / 'case_model.yaml')
    params = load_config(config) if not args.no_train else {}
    executor, close = _executor(args) if not args.train_only else (None, lambda: None)
    t_all = time.time()
    try:
        refused = 0
        for k, case in enumerate(cases, 1):
            print(f'[case {k}/{len(cases)}] {case.name}: {case.description}', flush=True)
            if case.scene.graded:  # a graded-library case: per-point store, gates
                refused += not _generate_graded(case, args, executor, params)
                continue
            res = generate_case(case, coarse=args.coarse, workers=args.workers, executor=executor,
                                sweep=not args.train_only, train=not args.no_train,
                                train_params=params, progress=not args.quiet,
                                cases=lib.cases())
            if res.failed:
                print(f'  warning: the FE load path failed at loading points {res.failed}; their '
                      'deepest depths are missing from the dataset', flush=True)
            print(f'  {res.samples or "-"} samples, FE {res.fe_elapsed_s:.0f} s elapsed '
                  f'({res.fe_solver_s:.0f} s solver time), training {res.train_s:.1f} s; wrote '
                  f'{", ".join(res.written) or "nothing"}', flush=True)
    finally:
        close()
    print(f'{len(cases)} case(s) in {time.time() - t_all:.0f} s'
          + (f'; {refused} refused' if refused else ''), flush=True)
    return 1 if refused else 0


def _generate_graded(case, args: argparse.Namespace, executor, params: dict) -> bool:
    """Sweep the missing points of a graded case into the store, then build it (grading, model,
    gates) unless --no-train; False (with one line naming the figure) when refused."""
    if not args.train_only:
        st = sweep_case_store(case, root=args.store, coarse=args.coarse, executor=executor,
                              workers=args.workers, progress=not args.quiet)
        print(f'  FE store: {st.solved}/{st.total} points solved'
              + (f', failed: {", ".join(st.failed)}' if st.failed else ''), flush=True)
    if args.no_train:
        return True
    try:
        res = build_case(case, store_root=args.store, coarse=args.coarse, train_params=params)
    except CaseError as exc:
        print(f'  refused: {exc}', flush=True)
        return False
    les = '; '.join(f'{g["lesion"]} {g["contrast_pct"]:+.1f} % ({g["contrast_n"]:+.3f} N) '
                    + (f'difficulty {g["difficulty"]} at {g["found_level"]}' if g['palpable']
                       else 'below what this device renders')
                    for g in res.grades) or 'no lesion'
    lvl = ('no level (every lesion below what this device renders)' if res.level is None
           else f'level {res.level}')
    print(f'  {lvl}: {les}; grouped-CV RMSE '
          + ', '.join(f'{v:.3f} N ({p:.2f} %)' for v, p in zip(res.cv_rmse_n, res.cv_pct_range))
          + f'; {res.bytes / 1024:.0f} KB; wrote {", ".join(res.written)}', flush=True)
    return True
