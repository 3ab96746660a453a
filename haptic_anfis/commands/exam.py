"""``haptic-anfis exam``: score a palpation session (examination mode).

``exam run``: the haptic graph (:func:`haptic_anfis.nodes.graph.build_graph`, the driver in its
default ``local_model`` force mode) with a simulated trainee at the simulated Falcon's hand and the
examiner in a process of its own, as ``sim``'s side nodes (:mod:`haptic_anfis.nodes.exam_side`;
``--in-process``: in the loop's process); ``exam report BAG``: the same
report from a recorded session. Both print the summary and, with ``--json``, end with one JSON
line (``coverage_pct`` {light, medium, deep}, ``duration_s``, ``hits``, ``misses``,
``false_marks``, ``score``, ``pattern``, ``verdict`` and more); ``--out DIR`` writes report.json
and report.png there.
"""
from __future__ import annotations

import argparse
import json
import math
import os
import shutil
import tempfile
import time
from pathlib import Path

import numpy as np
import yaml
from rclpy.parameter import Parameter

from ..cases.library import add_case_dir_argument, use_case_dir
from ..device.loop_health import behind_text
from ..exam.from_bag import new_session, resolve_exam_case, session_from_bag
from ..exam.normal import normal_lines, specificity_text
from ..exam.trainee import TraineeController, trainee_path
from ..exam.void import void_reason
from ..nodes.exam_side import CoverageWatch, examiner_arguments, hold_until_examiner
from ..nodes.examiner import Examiner, SAMPLES_FILE, write_report
from ..nodes.sim_trainee import SimTrainee
from ..realtime.processes import rerun_command_in_own_session
from ..session import OneProcessSession, add_session_arguments, spec_from_args
from ..tissue.scene import load_scene
from ._record import add_record_arguments, case_parameter, prepare_record, store_report
from .view import exam_debrief

NAME = 'exam'

#: [s] the longest ``exam run`` waits, after the trainee is done, for its marks to reach the
#: examiner
MARK_DRAIN_S = 10.0

#: [s] the longest ``exam run`` waits, once the exam is over, for the examiner in its own
#: process to write its report (it says so every 10 s meanwhile): everything scored is kept
#: unless the examiner is still writing after this long
EXAMINER_FINISH_S = 600.0

HEADLINE = ('coverage_pct', 'duration_s', 'contact_s', 'path_length_m', 'hits', 'misses',
            'false_marks', 'score', 'verdict', 'pattern')


def add_arguments(p: argparse.ArgumentParser) -> None:
    sub = p.add_subparsers(dest='exam_command', metavar='{run,report}', required=True)
    r = sub.add_parser('run', help='run the graph with the examiner and a simulated trainee')
    add_session_arguments(r, NAME)
    r.add_argument('--trainee', default='systematic', metavar='systematic|careless|SCRIPT',
                   help='simulated trainee: systematic, careless or a palpation script (YAML)')
    r.add_argument('--speed', type=float, default=None,
                   help="the trainee's speed along the tissue [m/s] (default: the script's)")
    r.add_argument('--force-mode', choices=('zoh', 'local_model'), default='local_model',
                   help="the falcon_driver's force_mode for the exam (default local_model, the "
                        "driver's default)")
    _common(r)
    add_record_arguments(r, run=True)
    b = sub.add_parser('report', help='score a recorded session bag')
    b.add_argument('bag', metavar='BAG')
    b.add_argument('--case', default=None, metavar='NAME',
                   help='case of the library (its surface and lesions) or a scene file (its '
                        'lesions) the session is scored against (default: the one the bag was '
                        'recorded with; the default case for a bag that does not say)')
    add_case_dir_argument(b)
    _common(b)
    add_record_arguments(b)


def _common(p):
    p.add_argument('--json', action='store_true', help='end with one line of JSON (the report)')
    p.add_argument('--out', metavar='DIR', default=None,
                   help='write report.json and report.png into DIR')
    p.add_argument('--exam-config', metavar='YAML', default=None,
                   help='scoring settings (default config/exam.yaml)')


def run(args: argparse.Namespace) -> int:
    use_case_dir(args.case_dir)   # before anything reads the library; the nodes inherit it
    if args.exam_command == 'run':
        # the loop's process in a session of its own, as sim's (a fair CPU share where the
        # kernel groups by session: beside 8 busy processes of the terminal's session and the
        # browser, the exam's start took minutes)
        code = rerun_command_in_own_session(args)
        if code is not None:
            return code
    felt = None
    prepare_record(args)
    if args.exam_command == 'run':
        report, session, felt = _run_sim(args)
    else:
        report, session = _report_bag(args)
    print_report(report)
    if args.out:
        if session is not None:
            write_report(session, args.out, report)
        else:   # the side examiner drew report.png; the report gained the trainee's part here
            (Path(args.out) / 'report.json').write_text(json.dumps(report, indent=1))
        print(f'report         {Path(args.out) / "report.json"}, {Path(args.out) / "report.png"}')
        if felt is not None:   # what the simulated trainee felt: its detector can be re-run on it
            np.save(Path(args.out) / 'trainee_felt.npy', felt)
            print(f'trainee felt   {Path(args.out) / "trainee_felt.npy"} ((n, 5): contact x, y, '
                  'z [m], depth [m], |F| [N])')
    status = store_report(args, report)
    if args.json:
        print(json.dumps(report), flush=True)
    if args.exam_command == 'run' and getattr(args, 'view', False):   # the page: the debrief
        exam_debrief(args, report, session)
    return status


#: the nodes of an exam session (the simulated trainee is the driver's simulated hand)
EXAM_NODES = ('falcon_driver', 'contact_detector', 'force_server', 'examiner')


def _run_sim(args):

    if args.speed is not None and not (args.speed > 0 and math.isfinite(args.speed)):
        raise ValueError(f'--speed: expected > 0 m/s, got {args.speed}')
    case, scene = resolve_exam_case(args.case or None)
    # the case for every node: its name, or for a blind session (--next) a seed that draws it
    # (no node then logs its name)
    case_name, case_value = case_parameter(args, case) if case is not None else (None, None)
    blind = case_name == 'random_case_seed'
    spec = spec_from_args(args, NAME, nodes=EXAM_NODES, case=case.name if case and not blind
                          else '', random_case=blind, seed=case_value if blind else None,
                          scene=scene or '')
    spec.check()
    script = trainee_path(args.trainee)
    sc = load_scene(scene) if scene else None
    scene_note = None
    if case is None and sc is not None:
        # A scene file changes the lesions scored; the default model and surface render
        # (resolve_exam_case): the trainee palpates that surface, not the file's breast.
        rendered = load_scene()
        if sc.radii != rendered.radii:
            mm = lambda r: 'x'.join(f'{1e3 * v:g}' for v in r)  # noqa: E731
            scene_note = (f'scene {scene} describes a {mm(sc.radii)} mm breast, but a scene file '
                          f'changes only the lesions scored: the default surface ('
                          f'{mm(rendered.radii)} mm) renders and the trainee palpates it (a '
                          'library case renders its own breast)')
            print(f'exam: {scene_note}', flush=True)
        sc = rendered
    # The trainee sees the breast (its size), never the lesions: scripts fit to the rendered
    # surface.
    controller = TraineeController.from_yaml(
        script, args.speed, breast=None if sc is None else (sc.radii, sc.palpable_radius))

    tmp = tempfile.TemporaryDirectory(prefix='haptic-anfis-exam-')
    fitted = Path(tmp.name) / 'trainee.yaml'   # the driver starts the hand where it begins
    fitted.write_text(yaml.safe_dump(controller.doc))
    ex_params = [Parameter('scene', value=scene or ''),
                 Parameter('exam_config', value=args.exam_config or '')]
    overrides = {'falcon_driver': [Parameter('palpation_script', value=str(fitted)),
                                   Parameter('force_mode', value=args.force_mode)]}
    if case_name is not None:
        ex_params.append(Parameter(case_name, value=case_value))
    # --- the examiner: in the loop's process (--in-process) or a process of its own
    report_dir, side_nodes = None, None
    if args.in_process:
        extra = [lambda ctx: Examiner(context=ctx, parameter_overrides=ex_params)]
    else:
        report_dir = tempfile.TemporaryDirectory(prefix='haptic-anfis-examiner-')
        side_nodes = {'examiner': examiner_arguments(
            scene or '', args.exam_config or '', None, report_dir.name,
            spec.params_arguments()[1::2])
            + (['-p', f'{case_name}:={case_value}'] if case_name else [])}
        extra = [lambda ctx: CoverageWatch(context=ctx)]
    extra.append(lambda ctx: SimTrainee(controller, context=ctx))
    # the examiner scores every sample: not a view to starve (nice 0)
    session = OneProcessSession(spec, extra=extra, overrides=overrides, side=False,
                                hand=controller, side_nodes=side_nodes, side_nice=0)
    try:
        graph = session.start()
    finally:
        tmp.cleanup()
    examiner = graph.extra[0]
    limit = args.duration if args.duration is not None else 300.0
    driver = graph.driver
    side = session.side
    # the examiner in a process of its own; the side processes may also be only the view's
    # (--in-process --view), with the examiner in this one
    own = side_nodes is not None
    if own:
        try:   # the examiner (another process) is up: hold the hand until it subscribed
            # as long as every other node may take to be ready: on a loaded machine its start
            # (imports, mesh, kernels) took longer than a minute
            if not hold_until_examiner(graph, spec.ready_timeout, watch=examiner,
                                       gone=side.dead):
                raise ValueError(
                    'exam: the examiner did not subscribe to the loop topics and publish its heat '
                    f'map in {spec.ready_timeout:g} s'
                    + ''.join(f'; {n} exited with code {c}' for n, c in side.dead()))
        except BaseException:
            session.stop()
            raise
    shown = (f'{case.name if case else "default (scene " + (scene or "default") + ")"}, examiner '
             + (f'in pid {side.pids["examiner"]}' if own else 'in this process'))
    print(f'exam: trainee {args.trainee} ({controller.search.duration:.0f} s search), case '
          f'{"blind" if getattr(args, "blind", False) else shown}', flush=True)
    if controller.search.duration > limit:
        print(f'exam: the search takes {controller.search.duration:.0f} s, longer than the time '
              f'limit ({limit:g} s, --duration): the exam will stop before the trainee finishes',
              flush=True)
    interrupted = False   # the trainee record stores no half session
    t_start = time.monotonic()
    loop_before = loop_counts(driver)   # a stall while the nodes started is not the exam's
    try:
        graph.spin_for(limit, lambda: controller.finished)
        # The executor may run seconds behind the 1 kHz loop on a loaded machine: wait until the
        # examiner has every mark the driver published (a stop right after the last click lost it).
        graph.spin_for(MARK_DRAIN_S, lambda: _examiner_marks(examiner) >= driver.clutch.marks)
        if not own:
            graph.spin_for(0.2)
        else:   # ... and every contact sample (it may run seconds behind: a 10 s deep queue)
            graph.spin_for(MARK_DRAIN_S, lambda: examiner.samples >= graph.contact.n_poses)
    except KeyboardInterrupt:
        print('interrupted', flush=True)
        interrupted = True
    finally:
        # the device to zero force; SIGINT: the examiner writes its report, and it may take
        # minutes on a loaded machine (the figure, the samples): wait for it, not a short grace
        session.stop(finish={'examiner': EXAMINER_FINISH_S} if own else None)
    session.print_recorded()
    if not own:
        report, exam_session = examiner.report(), examiner.session
        heat_maps = examiner.n_published
    else:
        report, exam_session = _side_report(report_dir, args.out, args if args.view else None)
        heat_maps = len(examiner.times)
        report['heat_map_hz'] = round(examiner.rate(t_start), 2)
        report['examiner_lost_contacts'] = lost_contacts(graph.contact.n_poses, report,
                                                        examiner.samples)
    report['interrupted'] = interrupted
    report['haptic_loop'], loop_note = haptic_loop(driver)
    if loop_note:
        report['notes'] = list(report.get('notes', [])) + [loop_note]
    # the machine's load must not count against the trainee: scored, kept, but void
    # (statistics reset meanwhile: what they count now is all after the start)
    during = {k: v - loop_before[k] if v >= loop_before[k] else v
              for k, v in loop_counts(driver).items()}
    report['haptic_loop']['during_exam'] = during
    report['void_reason'] = void_reason({**report['haptic_loop'], **during})
    if scene_note:
        report['notes'] = [scene_note] + list(report.get('notes', []))
    # cut off by --duration (or its 300 s default) before the trainee finished: not a whole exam
    report['time_limit_reached'] = cut = not interrupted and not controller.finished
    if cut:
        report['notes'] = [f'stopped at the time limit ({limit:g} s, --duration) before the '
                           'trainee finished its search: not a whole exam (its misses may be '
                           'the areas it had not reached yet)'] + list(report.get('notes', []))
    report['trainee'] = {'name': args.trainee, 'detections': [
        {'y_mm': round(d.y * 1e3, 2), 'z_mm': round(d.z * 1e3, 2),
         'excess_pct': round(100 * d.excess, 1), 'sigma': round(d.sigma, 1)}
        for d in controller.detections or []], 'finished': controller.finished,
        'felt_samples': controller.felt}
    report['heat_maps_published'] = heat_maps
    report['case'] = case.name if case else (scene or 'default')
    # drawn by --next: the record names the case to the instructor only
    report['blind'] = bool(getattr(args, 'blind', False))
    report['force_mode'] = args.force_mode
    mapping = spec.force_mapping()   # the tissue -> device force scale the driver rendered
    report['force_mapping'] = None if mapping is None else mapping.as_dict()
    report['examiner_process'] = 'own' if own else 'loop'
    report['own_session'] = os.getsid(0) == os.getpid()
    return report, exam_session, controller.felt_array()


def _examiner_marks(examiner) -> int:
    """Marks the examiner has: the in-process node's session, or the side examiner's last heat
    map text (:class:`~haptic_anfis.nodes.exam_side.CoverageWatch`)."""
    return len(examiner.session.marks) if hasattr(examiner, 'session') else examiner.marks


def lost_contacts(published: int, report: dict, watched: int) -> int:
    """Contact samples missing from the side examiner's report: ``published`` (the contact
    detector's count) minus those its session holds (the report's ``samples.contact``; without
    it, ``watched``: the count its last heat map gave). Samples that arrived late, after the
    exam's drain but before the examiner wrote its report, are not missing."""
    got = (report.get('samples') or {}).get('contact', watched)
    return max(int(published) - int(got), 0)


def _side_report(report_dir, out: str | None, view_args=None):
    """The side examiner's report.json (and report.png into ``out``); with ``view_args`` (``exam
    run --view``) also its session rebuilt from the raw samples it saved (for the debrief), else
    None."""
    d = Path(report_dir.name)
    try:   # written last and whole: its presence says the samples and figure are there
        report = json.loads((d / 'report.json').read_text())
    except (OSError, ValueError) as exc:
        raise ValueError(f'exam: the examiner (its own process) wrote no report within '
                         f'{EXAMINER_FINISH_S:g} s of the end of the exam ({exc}); its log is '
                         'above') from None
    if out and (d / 'report.png').is_file():
        Path(out).mkdir(parents=True, exist_ok=True)
        shutil.copy(d / 'report.png', Path(out) / 'report.png')
    session = None
    if view_args is not None:
        session = new_session(view_args.case or None, view_args.exam_config)
        session.load_samples(d / SAMPLES_FILE)
    report_dir.cleanup()
    return report, session


def _report_bag(args):
    return session_from_bag(args.bag, args.case, args.exam_config)


#: the driver's loop figures an exam report carries (``haptic_loop``)
LOOP_KEYS = ('rate_hz', 'periods_lost', 'max_gap_ms', 'gaps_past_watchdog', 'loop_windows',
             'loop_windows_behind', 'servo_scheduling')


#: the loop counts that grow with time (check windows, those behind, gaps past the watchdog)
LOOP_COUNTS = ('loop_windows', 'loop_windows_behind', 'gaps_past_watchdog')


def loop_counts(driver) -> dict[str, int]:
    """The driver's loop counts so far (:data:`LOOP_COUNTS`): taken at the exam's start and end,
    their difference is the exam's own."""
    s = driver.summary()
    return {k: int(s.get(k) or 0) for k in LOOP_COUNTS}


def haptic_loop(driver) -> tuple[dict, str | None]:
    """(the servo loop's figures over the exam, from the falcon driver's summary; a note for
    the report when any of its ``loop_check_period`` windows fell behind, else None): the
    instructor reading the report then knows whether the forces the trainee felt came late."""
    s = driver.summary()
    loop = {k: s.get(k) for k in LOOP_KEYS}
    text = behind_text(int(loop['loop_windows'] or 0), int(loop['loop_windows_behind'] or 0),
                       driver.behind_because())
    return loop, (f'haptic loop: {text}' if text else None)


def print_report(r: dict) -> None:
    c = r['coverage_pct']
    print(f"coverage       light {c['light']:.1f} %, medium {c['medium']:.1f} %, deep "
          f"{c['deep']:.1f} % of {r['region_faces']} cells (radius {r['region_radius_mm']:.0f} mm)")
    print(f"pattern        {r['pattern']} ({r['pattern_detail']['strips']['count']} strips, "
          f"overlap {r['pattern_detail']['strips']['overlap']}, gaps "
          f"{r['pattern_detail']['strips']['gaps']})")
    print(f"time           {r['duration_s']:.1f} s, in contact {r['contact_s']:.1f} s, path "
          f"{r['path_length_m']:.2f} m, max depth {r['max_depth_mm']:.1f} mm")
    lv = r.get('time_at_level_s')
    if lv:   # what predicts finding lumps (exam/effort.py); not in a report made before it
        print('pressure time  ' + ', '.join(f"{k.replace('_', ' ')} {v:.1f} s"
                                             for k, v in lv.items()))
        print('area time      ' + ', '.join(f'{k} {v:.1f} s'
                                             for k, v in r['area_time_s'].items()))
        fp, fs = r.get('force_palpating_n'), r.get('force_searching_n')
        print(f"force          palpating {'-' if fp is None else f'{fp:.2f} N'} "
              f"({r['palpating_s']:.1f} s), searching {'-' if fs is None else f'{fs:.2f} N'} "
              f"({r['searching_s']:.1f} s)"
              + ('' if r.get('palpating_vs_searching_pct') is None else
                 f", palpating {r['palpating_vs_searching_pct']:+.0f} % (successful examiners "
                 'press ~15 % harder palpating)'))
    print(f"findings       hits {r['hits']}, misses {r['misses']}, false marks {r['false_marks']}"
          + specificity_text(r))
    for les in r['lesions']:
        where = (f", felt from {les['level']} pressure ({les['level_depth_mm']:g} mm)"
                 if les.get('level') else '')
        print(f"  lesion {les['name']}: {'found' if les['found'] else les['missed']}{where}"
              + (f" ({les['reason']})" if les.get('reason') else ''))
    for line in normal_lines(r):
        print(f'  {line}')
    print(f"score          {r['score']:.1f} ({r['verdict']})")
    if r.get('void_reason'):
        print(f"void           {r['void_reason']}")
    loop = r.get('haptic_loop')   # exam run only: a bag's report has no loop figures
    if loop and loop.get('rate_hz') is not None:
        print(f"haptic loop    {loop['rate_hz']:.1f} Hz, {loop['loop_windows_behind']} of "
              f"{loop['loop_windows']} check windows behind, {loop['gaps_past_watchdog']} gaps "
              'past the watchdog')
    for line in r['feedback']:
        print(f'  - {line}')
    for n in r['notes']:
        print(f'note: {n}')
