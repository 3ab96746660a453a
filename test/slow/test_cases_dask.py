"""`cases generate --dask ADDRESS` on a real dask.distributed cluster: a scheduler and two workers
started as separate processes (`dask scheduler`, `dask worker`), a tiny graded case on the coarse
mesh. One worker is killed mid-sweep: every point still ends up in the per-point store, and the
solve journal shows no point solved twice."""
import os
import signal
import threading
import subprocess
import sys
import time
from pathlib import Path

import pytest
import yaml

pytest.importorskip('distributed')

from haptic_anfis.cases import CaseLibrary  # noqa: E402
from haptic_anfis.cases.sweeps import case_stores, store_status  # noqa: E402
from haptic_anfis.tissue.pointsweep import JOURNAL_ENV  # noqa: E402

pytestmark = pytest.mark.slow

#: 9 base points, a lesion's centre, mirror point and one ring of 4: 15 points + 1 twin point
TINY = {
    'name': 'tinydask', 'description': 'test case for the dask sweep',
    'breast': {'radii_mm': [45, 70, 70]},
    'material': {'youngs_kPa': 33, 'poisson': 0.499},
    'tumours': [{'name': 'idc', 'kind': 'malignant', 'position_mm': [12, 6], 'depth_mm': 10,
                 'radius_mm': 5, 'youngs_kPa': 93}],
    'probe': {'diameter_mm': 16},
    'loading': {'spacing_mm': 20, 'palpable_radius_mm': 30, 'ring_diameters': [1.0],
                'ring_points': 4, 'depths_mm': [2, 5], 'max_step_mm': 3},
    'mesh': {'probe_cells': 4, 'coarse_probe_cells': 2, 'edge_offset': 0.2, 'edge_refine': 0},
}


def _dask(*args: str, env: dict) -> subprocess.Popen:
    """`dask ARGS` from this interpreter's environment, in its own process group."""
    exe = Path(sys.executable).with_name('dask')
    cmd = [str(exe), *args] if exe.is_file() else [sys.executable, '-m', 'dask', *args]
    return subprocess.Popen(cmd, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                            start_new_session=True)


def test_generate_on_a_dask_cluster_survives_a_killed_worker(tmp_path, capsys):
    from distributed import Client

    from haptic_anfis.cli import main

    scenes, data, store = tmp_path / 'scenes', tmp_path / 'data', tmp_path / 'store'
    scenes.mkdir()
    (scenes / 'tinydask.yaml').write_text(yaml.safe_dump(TINY))
    journal = tmp_path / 'journal.txt'
    env = {**os.environ, JOURNAL_ENV: str(journal), 'OMP_NUM_THREADS': '1',
           'OPENBLAS_NUM_THREADS': '1', 'MKL_NUM_THREADS': '1',
           'PYTHONPATH': os.pathsep.join([str(Path(__file__).resolve().parents[2]),
                                          os.environ.get('PYTHONPATH', '')])}
    sched_file = tmp_path / 'scheduler.json'
    procs = [_dask('scheduler', '--scheduler-file', str(sched_file), '--port', '0',
                   '--no-dashboard', env=env)]
    try:
        deadline = time.time() + 30
        while not sched_file.is_file() and time.time() < deadline:
            time.sleep(0.2)
        assert sched_file.is_file(), 'dask scheduler did not start'
        for _ in range(2):
            procs.append(_dask('worker', '--scheduler-file', str(sched_file), '--nthreads', '1',
                               '--no-nanny', '--no-dashboard', env=env))
        with Client(scheduler_file=str(sched_file), timeout=30) as client:
            client.wait_for_workers(2, timeout=60)
            address = client.scheduler.address
        # the CLI opens its own client (one client at a time in this process)
        lib = CaseLibrary(scenes, data)
        stores = case_stores(lib.get('tinydask'), store, coarse=True)
        total = store_status(stores).total
        # kill one worker once a few points are on disk

        killed = {}

        def killer():
            end = time.time() + 120
            while time.time() < end:
                if len(stores.main.solved()) >= 3:
                    os.killpg(procs[1].pid, signal.SIGKILL)
                    killed['at'] = len(stores.main.solved())
                    return
                time.sleep(0.05)

        th = threading.Thread(target=killer, daemon=True)
        th.start()
        rc = main(['cases', 'generate', 'tinydask', '--dask', address, '--coarse',
                   '--no-train', '--quiet', '--scene-dir', str(scenes), '--data-dir', str(data),
                   '--store', str(store)])
        th.join(timeout=5)
        out = capsys.readouterr().out
        assert rc == 0, out
        assert killed, 'the sweep finished before a worker could be killed'
        st = store_status(stores)
        assert st.complete and st.solved == total == 16
        assert f'FE store: {total}/{total} points solved' in out
        lines = journal.read_text().split('\n')[:-1]
        assert len(lines) == len(set(lines)), 'a point was solved twice'
        assert len(lines) <= total
        # a second run finds everything on disk: nothing is solved again
        n_before = len(lines)
        assert main(['cases', 'sweep', 'tinydask', '--coarse', '--quiet', '--workers', '1',
                     '--scene-dir', str(scenes), '--data-dir', str(data),
                     '--store', str(store)]) == 0
        assert len(journal.read_text().split('\n')[:-1]) == n_before
    finally:
        for p in procs:
            try:
                os.killpg(p.pid, signal.SIGKILL)
            except ProcessLookupError:
                pass
            p.wait(timeout=10)
