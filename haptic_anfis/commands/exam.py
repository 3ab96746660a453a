"""``haptic-anfis exam``: score a palpation session (examination mode).

``exam run``: the one-process haptic graph (:func:`haptic_anfis.nodes.graph.build_graph`) with the
examiner and a simulated trainee at the simulated Falcon's hand; ``exam report BAG``: the same
report from a recorded session. Both print the summary and, with ``--json``, end with one JSON
line (``coverage_pct`` {light, medium, deep}, ``duration_s``, ``hits``, ``misses``,
``false_marks``, ``score``, ``pattern``, ``verdict`` and more); ``--out DIR`` writes report.json
and report.png there.
"""
from __future__ import annotations

import argparse
import json
import math
from pathlib import Path

NAME = 'exam'
HELP = 'examination mode: run a simulated trainee through an exam, or score a recorded session'

#: [s] the longest ``exam run`` waits, after the trainee is done, for its marks to reach the
#: examiner
MARK_DRAIN_S = 10.0

HEADLINE = ('coverage_pct', 'duration_s', 'contact_s', 'path_length_m', 'hits', 'misses',
            'false_marks', 'score', 'verdict', 'pattern')


def add_arguments(p: argparse.ArgumentParser) -> None:
    sub = p.add_subparsers(dest='exam_command', metavar='{run,report}', required=True)
    r = sub.add_parser('run', help='run the graph with the examiner and a simulated trainee')
    r.add_argument('--case', default=None, metavar='NAME',
                   help='case of the library (haptic-anfis cases list: its model, surface and '
                        'lesions) or a scene file (its lesions, default model) (default: default)')
    r.add_argument('--trainee', default='systematic', metavar='systematic|careless|SCRIPT',
                   help='simulated trainee: systematic, careless or a palpation script (YAML)')
    r.add_argument('--speed', type=float, default=None,
                   help="the trainee's speed along the tissue [m/s] (default: the script's)")
    r.add_argument('--duration', type=float, default=None,
                   help='stop after this many seconds (default: when the trainee is done, '
                        'at most 300 s)')
    r.add_argument('--record', metavar='BAG', default=None,
                   help='record the session (loop topics + marks) to this new bag directory')
    r.add_argument('--force-mode', choices=('zoh', 'local_model'), default='zoh',
                   help="the falcon_driver's force_mode for the exam (default zoh: on the shared "
                        '2-core machine the one-process exam graph in local_model mode fell to a '
                        '~280 Hz servo and starved the examiner, see the README)')
    r.add_argument('--params-file', action='append', default=[], metavar='YAML',
                   help='ROS 2 parameter file for the nodes (repeatable; the exam sets the '
                        "driver's palpation_script and force_mode itself)")
    _common(r)
    from .view import add_view_arguments
    add_view_arguments(r, hold=True)
    b = sub.add_parser('report', help='score a recorded session bag')
    b.add_argument('bag', metavar='BAG')
    b.add_argument('--case', default=None, metavar='NAME',
                   help='case of the library (its surface and lesions) or a scene file (its '
                        'lesions) the session is scored against (default: default)')
    _common(b)


def _common(p):
    p.add_argument('--json', action='store_true', help='end with one line of JSON (the report)')
    p.add_argument('--out', metavar='DIR', default=None,
                   help='write report.json and report.png into DIR')
    p.add_argument('--exam-config', metavar='YAML', default=None,
                   help='scoring settings (default config/exam.yaml)')


def resolve_exam_case(case: str | None, need: tuple[str, ...] = ('model_path', 'mesh_path'),
                      lib=None):
    """:func:`haptic_anfis.exam.from_bag.resolve_exam_case` (imported when called: the CLI
    builds every parser at start)."""
    from ..exam.from_bag import resolve_exam_case as resolve
    return resolve(case, need, lib)


def run(args: argparse.Namespace) -> int:
    felt = None
    if args.exam_command == 'run':
        report, session, felt = _run_sim(args)
    else:
        report, session = _report_bag(args)
    print_report(report)
    if args.out:
        from ..nodes.examiner import write_report
        write_report(session, args.out, report)
        print(f'report         {Path(args.out) / "report.json"}, {Path(args.out) / "report.png"}')
        if felt is not None:   # what the simulated trainee felt: its detector can be re-run on it
            import numpy as np
            np.save(Path(args.out) / 'trainee_felt.npy', felt)
            print(f'trainee felt   {Path(args.out) / "trainee_felt.npy"} ((n, 5): contact x, y, '
                  'z [m], depth [m], |F| [N])')
    if args.json:
        print(json.dumps(report), flush=True)
    if args.exam_command == 'run':   # --view: the page turns into the debrief
        from .view import exam_debrief
        exam_debrief(args, report, session, getattr(args, 'view_side', None))
    return 0


def _run_sim(args):
    from rclpy.parameter import Parameter

    from ..exam.trainee import TraineeController, trainee_path
    from ..nodes._common import ParameterError
    from ..nodes.examiner import Examiner
    from ..nodes.graph import build_graph
    from ..nodes.sim_trainee import SimTrainee
    if args.record and Path(args.record).exists():
        raise ValueError(f'--record {args.record}: exists already; a recording needs a new '
                         'directory')
    if args.duration is not None and not (args.duration > 0 and math.isfinite(args.duration)):
        raise ValueError(f'--duration: expected > 0 s, got {args.duration}')
    if args.speed is not None and not (args.speed > 0 and math.isfinite(args.speed)):
        raise ValueError(f'--speed: expected > 0 m/s, got {args.speed}')
    from ..tissue.scene import load_scene
    case, scene = resolve_exam_case(args.case)
    script = trainee_path(args.trainee)
    sc = load_scene(scene) if scene else None
    # The trainee sees the breast (its size), never the lesions: scripts fit to the case's surface.
    controller = TraineeController.from_yaml(
        script, args.speed, breast=None if sc is None else (sc.radii, sc.palpable_radius))
    import tempfile

    import yaml
    tmp = tempfile.TemporaryDirectory(prefix='haptic-anfis-exam-')
    fitted = Path(tmp.name) / 'trainee.yaml'   # the driver starts the hand where it begins
    fitted.write_text(yaml.safe_dump(controller.doc))
    ex_params = [Parameter('scene', value=scene or ''),
                 Parameter('exam_config', value=args.exam_config or '')]
    overrides = {'falcon_driver': [Parameter('palpation_script', value=str(fitted)),
                                   Parameter('force_mode', value=args.force_mode)]}
    if case is not None:   # model, surface and lesions of the case in every node
        for node in ('contact_detector', 'force_server'):
            overrides[node] = [Parameter('case', value=case.name)]
        ex_params.append(Parameter('case', value=case.name))
    extra = [lambda ctx: Examiner(context=ctx, parameter_overrides=ex_params),
             lambda ctx: SimTrainee(controller, context=ctx)]
    if args.record:
        from ..bag.topics import ALL_LOOP_TOPICS
        from ..nodes.recorder import Recorder
        extra.append(lambda ctx: Recorder(context=ctx, output=args.record, topics=ALL_LOOP_TOPICS))
    try:
        ros_args = ['--ros-args', *[a for f in args.params_file for a in ('--params-file', f)]] \
            if args.params_file else []
        graph = build_graph(['haptic-anfis-exam', *ros_args], visualizer=False, extra=extra,
                            overrides=overrides)
    except ParameterError as exc:
        raise ValueError(str(exc)) from None
    finally:
        tmp.cleanup()
    from .view import start_side_view   # --view: the live page, in a process of its own
    try:
        args.view_side = start_side_view(args, ['-p', f'case:={case.name}'] if case else [])
    except BaseException:
        graph.shutdown()
        raise
    # The driver's simulated Falcon plays the trainee (same start point as the script it loaded).
    graph.driver.device.script = controller
    examiner = graph.extra[0]
    limit = args.duration if args.duration is not None else 300.0
    print(f'exam: trainee {args.trainee} ({controller.search.duration:.0f} s search), case '
          f'{case.name if case else "default (scene " + (scene or "default") + ")"}, lesions from '
          f'{examiner.subject.source}', flush=True)
    driver = graph.driver
    try:
        graph.spin_for(limit, lambda: controller.finished)
        # The executor may run seconds behind the 1 kHz loop on a loaded machine: wait until the
        # examiner has every mark the driver published (a stop right after the last click lost it).
        graph.spin_for(MARK_DRAIN_S, lambda: len(examiner.session.marks) >= driver.clutch.marks)
        graph.spin_for(0.2)
    except KeyboardInterrupt:
        print('interrupted', flush=True)
    finally:
        graph.shutdown()
    for n in graph.extra:
        if hasattr(n, 'writer'):
            r = n.summary()
            print(f"recorded       {r['written']} messages to {r['output']} (dropped {r['dropped']})")
    report = examiner.report()
    report['trainee'] = {'name': args.trainee, 'detections': [
        {'y_mm': round(d.y * 1e3, 2), 'z_mm': round(d.z * 1e3, 2),
         'excess_pct': round(100 * d.excess, 1), 'sigma': round(d.sigma, 1)}
        for d in controller.detections or []], 'finished': controller.finished,
        'felt_samples': controller.felt}
    report['heat_maps_published'] = examiner.n_published
    report['case'] = case.name if case else (scene or 'default')
    report['force_mode'] = args.force_mode
    return report, examiner.session, controller.felt_array()


def _report_bag(args):
    from ..exam.from_bag import session_from_bag
    return session_from_bag(args.bag, args.case, args.exam_config)


def print_report(r: dict) -> None:
    c = r['coverage_pct']
    print(f"coverage       light {c['light']:.1f} %, medium {c['medium']:.1f} %, deep "
          f"{c['deep']:.1f} % of {r['region_faces']} cells (radius {r['region_radius_mm']:.0f} mm)")
    print(f"pattern        {r['pattern']} ({r['pattern_detail']['strips']['count']} strips, "
          f"overlap {r['pattern_detail']['strips']['overlap']}, gaps "
          f"{r['pattern_detail']['strips']['gaps']})")
    print(f"time           {r['duration_s']:.1f} s, in contact {r['contact_s']:.1f} s, path "
          f"{r['path_length_m']:.2f} m, max depth {r['max_depth_mm']:.1f} mm")
    print(f"findings       hits {r['hits']}, misses {r['misses']}, false marks {r['false_marks']}")
    for les in r['lesions']:
        print(f"  lesion {les['name']}: {'found' if les['found'] else les['missed']}")
    print(f"score          {r['score']:.1f} ({r['verdict']})")
    for line in r['feedback']:
        print(f'  - {line}')
    for n in r['notes']:
        print(f'note: {n}')
