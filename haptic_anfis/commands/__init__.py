"""Sub-commands of ``haptic-anfis``: one module each, ``haptic_anfis.commands.<word>``, listed in
:data:`COMMANDS` (see :mod:`haptic_anfis.cli`).

The table holds each command's one-line help so that ``haptic-anfis --help`` lists every command
without importing any of them; the command typed is the only module imported, and it imports what
it needs at its top.
"""

__all__ = ['COMMANDS']

#: {the word typed after ``haptic-anfis``: its one-line help}; the module is
#: ``haptic_anfis.commands.<word>``, defining ``add_arguments(parser)`` and ``run(args) -> int``.
COMMANDS: dict[str, str] = {
    'bag': 'record, play, inspect, export, recover and re-simulate rosbag2 session bags',
    'bench': 'benchmarks (printed, never asserted): "model" = speed against error of the ANFIS '
             'models',
    'cases': 'list the palpation case library, or generate cases (FE sweep, mesh, model)',
    'dataset': 'generate the FE force dataset (and surface mesh, validation report) for a tissue '
               'scene',
    'demo': 'train the force models on the shipped dataset; print test RMSE and evaluation speed',
    'evaluate': 'evaluate a model file on a force dataset (RMSE and max error per output)',
    'exam': 'examination mode: run a simulated trainee through an exam, or score a recorded '
            'session',
    'falcon': 'check a real Novint Falcon step by step, and calibrate its force scale',
    'launch': 'run the haptic nodes as separate processes (falcon_driver, contact_detector, ...)',
    'loop': 'applied-force error and loop statistics of a falcon_driver servo tick trace '
            '(trace_path)',
    'report': 'speed-against-error report: our ANFIS models and peers (xanfis, RBF, k-NN, MLP, '
              'linear) on one split; writes report.md + PNG figures',
    'sim': 'run the haptic node graph in one process with the simulated Falcon and print loop '
           'statistics',
    'threshold': "measure a trainee's stiffness-discrimination threshold (2AFC staircase) on the "
                 'device',
    'topic': "list topics, echo messages (readable fields), measure a topic's rate",
    'train': 'train the Fx/Fy/Fz ANFIS models on a force dataset (structure search, hybrid '
             'learning)',
    'trainees': 'the trainee record: list trainees, show sessions, progress and mastery, export, '
                'delete',
    'view': "the trainee's screen in a browser: the debrief of a recorded session (coverage per "
            'level, path, marks, lesions revealed, score, replay)',
    'warmup': "compile the nodes' numba kernels (force model, contact detector, servo tick) into "
              'the cache (run once after install)',
}
