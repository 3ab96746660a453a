"""Per-point FE results on disk: one small compressed file per (case, loading point).

A full-density library is many CPU-hours, solved across sessions and machines, so every solved
loading point is written at once as its own file and a sweep only solves what is missing:

    <root>/<case>/manifest.json                  scene hash, mesh density, depths: what the points
                                                 belong to (a mismatch is refused, never mixed)
    <root>/<case>/y+018000_z+015000.npz          one solved point (y, z in micrometres); status
                                                 'partial' when the solve stopped before the
                                                 deepest depths (it keeps those it reached and
                                                 names the missing ones)
    <root>/<case>/y+018000_z+015000.failed.json  a point that reached no depth (named when a
                                                 case is refused; never silently dropped)
    <root>/<case>/twin/...                       the same layout for the lesion-free twin (the
                                                 scene without its lesions), solved only where a
                                                 lesion's contrast is measured

A point file holds only what the shipped files need, float32 and compressed (a few KB): forces
at every depth, the skin displacement harmonics the displacement file uses
(:mod:`.displacement`), and a JSON ``meta`` (solver figures, attempt, times). The surface point,
direction and depths stay float64 (they are the dataset's inputs). Writes are atomic
(temporary file + rename in the same directory): a killed writer leaves no torn file.

The directory is meant to be committed (``fe_store/`` in the source tree), so a sweep resumes in
the next session. SI units (m, N).
"""
from __future__ import annotations

import io
import json
import os
import re
import tempfile
from pathlib import Path
from typing import Any, Iterable

import numpy as np

from ..errors import HapticAnfisError

__all__ = ['FORMAT_VERSION', 'PointStore', 'StoreError', 'default_store_root', 'failed_records',
           'failure_summary', 'point_key', 'store_manifest']

FORMAT_VERSION = 1


class StoreError(HapticAnfisError, ValueError):
    """A store directory belongs to another scene/mesh, or a point file is unreadable."""


def default_store_root() -> Path:
    """``fe_store/`` at the top of the source tree (committed, so sweeps resume across
    sessions); ``./fe_store`` when running from an installed package."""
    src = Path(__file__).resolve().parents[2]
    if (src / 'setup.py').is_file():
        return src / 'fe_store'
    return Path('fe_store').resolve()


def failed_records(directory: str | os.PathLike) -> dict[str, dict[str, Any]]:
    """{key: failure record} of the points in the store ``directory`` whose every attempt failed
    ({} when there is no such directory). Reads no manifest: a caller that only reports why a case
    is not ready need not know the scene's mesh density."""
    d = Path(directory)
    if not d.is_dir():
        return {}
    return {p.name[:-len('.failed.json')]: json.loads(p.read_text())
            for p in sorted(d.glob('*.failed.json'))}


def failure_summary(error: str) -> str:
    """One line of a failure record's ``error`` (every attempt's message, joined by '; '): how
    many attempts failed and the last one's load step, depth reached and cause, without the
    solver's trailing detail."""
    parts = [p.strip() for p in re.split(r';\s*(?=attempt \d)', error.strip()) if p.strip()]
    if not parts:
        return 'failed'
    m = re.match(r'attempt \d+ \(step ([^)]*)\): (.*)', parts[-1], re.S)
    if m is None:
        return parts[-1].splitlines()[0]
    cause = ': '.join(m.group(2).split(': ')[:2]).rstrip('.')
    return f'{len(parts)} attempt(s) failed, the last (load step {m.group(1)}) {cause}'


def point_key(y: float, z: float) -> str:
    """File stem of the loading point over (y, z) [m]: 'y+018000_z-015000' (micrometres)."""
    return f'y{int(round(y * 1e6)):+07d}_z{int(round(z * 1e6)):+07d}'


def store_manifest(scene, probe_cells: int) -> dict[str, Any]:
    """What a store directory's points belong to: the scene's hash (and that of its FE problem
    alone, which another scene of another name may share), mesh density and depths."""
    return {'format_version': FORMAT_VERSION, 'scene': scene.name, 'scene_sha256': scene.sha256(),
            'fe_sha256': scene.fe_sha256(),
            'probe_cells': int(probe_cells), 'edge_refine': scene.mesh.edge_refine,
            'edge_offset': scene.mesh.edge_offset,
            'depths_m': [float(d) for d in scene.depths]}


def _atomic_bytes(path: Path, data: bytes) -> None:
    fd, tmp = tempfile.mkstemp(prefix='.' + path.name + '.', suffix='.tmp', dir=path.parent)
    try:
        with os.fdopen(fd, 'wb') as f:
            f.write(data)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, path)
    except BaseException:
        if os.path.exists(tmp):
            os.unlink(tmp)
        raise


class PointStore:
    """The solved points of one scene at one mesh density, in ``directory``.

    Args:
        directory: ``<root>/<case>`` (or ``<root>/<case>/twin``); created on first write.
        manifest: :func:`store_manifest` of the scene and density; an existing directory with
            another manifest raises :class:`StoreError` naming both hashes. Two manifests that
            both carry ``fe_sha256`` match on it (the FE problem), not on the scene's own hash
            (which includes its name): a scene may read another scene's store when they solve
            the same problem (``fe_store`` in the scene file).
    """

    def __init__(self, directory: str | os.PathLike, manifest: dict[str, Any]) -> None:
        self.dir = Path(directory)
        self.manifest = dict(manifest)
        mpath = self.dir / 'manifest.json'
        if mpath.is_file():
            old = json.loads(mpath.read_text())
            h = 'fe_sha256' if old.get('fe_sha256') and self.manifest.get('fe_sha256') \
                else 'scene_sha256'
            keys = ('format_version', h, 'probe_cells', 'edge_refine', 'edge_offset', 'depths_m')
            if any(old.get(k) != self.manifest.get(k) for k in keys):
                raise StoreError(
                    f'FE store {str(self.dir)!r} holds points of {h[:-7].replace("_", " ")} hash '
                    f'{str(old.get(h))[:12]} at {old.get("probe_cells")} cells across '
                    f'the probe, not {str(self.manifest.get(h))[:12]} at '
                    f'{self.manifest["probe_cells"]}: the scene or the mesh changed; move that '
                    'directory away to solve afresh')

    # -- paths -------------------------------------------------------------------------------
    def path(self, key: str) -> Path:
        return self.dir / f'{key}.npz'

    def failed_path(self, key: str) -> Path:
        return self.dir / f'{key}.failed.json'

    def _ensure_dir(self) -> None:
        if not (self.dir / 'manifest.json').is_file():
            self.dir.mkdir(parents=True, exist_ok=True)
            _atomic_bytes(self.dir / 'manifest.json',
                          (json.dumps(self.manifest, indent=1) + '\n').encode())

    # -- queries -----------------------------------------------------------------------------
    def solved(self) -> set[str]:
        """Keys of every solved point on disk."""
        if not self.dir.is_dir():
            return set()
        return {p.name[:-4] for p in self.dir.glob('*.npz') if not p.name.startswith('.')}

    def failed(self) -> dict[str, dict[str, Any]]:
        """{key: failure record} of the points whose every attempt failed."""
        return failed_records(self.dir)

    def partial(self) -> dict[str, list[float]]:
        """{key: missing depths [m]} of the point files whose solve stopped before the deepest
        depths (reads only each file's small ``meta``)."""
        out = {}
        for key in sorted(self.solved()):
            meta = self._meta(key)
            if meta.get('status') == 'partial':
                out[key] = [float(d) for d in meta.get('missing_depths_m', [])]
        return out

    def has(self, key: str) -> bool:
        return self.path(key).is_file()

    # -- read / write ------------------------------------------------------------------------
    def save(self, key: str, rec: dict[str, Any]) -> Path:
        """Write one solved point (a :func:`record_to_arrays` input: the sweep record) atomically;
        clears a failure record of the same point."""
        self._ensure_dir()
        arrays = record_to_arrays(rec)
        buf = io.BytesIO()
        np.savez_compressed(buf, **arrays)
        path = self.path(key)
        _atomic_bytes(path, buf.getvalue())
        if self.failed_path(key).is_file():
            self.failed_path(key).unlink()
        return path

    def save_failure(self, key: str, rec: dict[str, Any]) -> Path:
        """Record a point whose every attempt failed (error, depth reached, attempts)."""
        self._ensure_dir()
        keep = {k: rec.get(k) for k in ('surface_point_m', 'status', 'error', 'attempts',
                                        'depths_m', 'wall_time_s', 'cpu_time_s')}
        path = self.failed_path(key)
        _atomic_bytes(path, (json.dumps(keep, indent=1) + '\n').encode())
        return path

    def save_record(self, key: str, rec: dict[str, Any]) -> Path | None:
        """Write a sweep record by its status: 'ok' always; 'partial' unless the point file on
        disk already reaches as deep; 'failed' unless a point file exists (a failed retry never
        hides the depths a partial point reached). The path written, or None."""
        if rec['status'] == 'ok':
            return self.save(key, rec)
        if self.has(key):
            old = self._meta(key)
            if old.get('status', 'ok') != 'partial' or rec['status'] != 'partial' \
                    or len(rec['depths_m']) <= len(self.load(key)['depths_m']):
                return None
        if rec['status'] == 'partial':
            return self.save(key, rec)
        return self.save_failure(key, rec)

    def _meta(self, key: str) -> dict[str, Any]:
        """The JSON ``meta`` of a point file."""
        path = self.path(key)
        try:
            with np.load(path, allow_pickle=False) as z:
                return json.loads(str(z['meta']))
        except (OSError, ValueError, KeyError) as exc:
            raise StoreError(f'FE store point {str(path)!r} is unreadable: {exc}') from None

    def load(self, key: str) -> dict[str, Any]:
        """The sweep record of a solved point (forces, displacement profile, meta)."""
        path = self.path(key)
        try:
            with np.load(path, allow_pickle=False) as z:
                arrays = {k: z[k] for k in z.files}
        except (OSError, ValueError, KeyError) as exc:
            raise StoreError(f'FE store point {str(path)!r} is unreadable: {exc}') from None
        return arrays_to_record(arrays)

    def load_many(self, keys: Iterable[str]) -> dict[str, dict[str, Any]]:
        return {k: self.load(k) for k in keys}


# -- record <-> arrays ---------------------------------------------------------------------------
_META_KEYS = ('status', 'ndof', 'ncells', 'probe_edge_m', 'newton_iterations', 'cutbacks',
              'wall_time_s', 'cpu_time_s', 'linear_solver', 'attempt', 'max_step_m', 'solver_info',
              'scene_sha256', 'missing_depths_m', 'error', 'attempts')


def record_to_arrays(rec: dict[str, Any]) -> dict[str, np.ndarray]:
    """The arrays of a point file from a sweep record (``sweep._solve_task``'s dict)."""
    disp = rec.get('displacement') or {}
    meta = {k: rec[k] for k in _META_KEYS if k in rec}
    meta['displacement'] = {k: disp[k] for k in ('grid_version', 'n_angles', 'harmonics',
                                                 'components', 'footprint_radius_m') if k in disp}
    out = {'surface_point': np.asarray(rec['surface_point_m'], dtype=np.float64),
           'direction': np.asarray(rec['direction'], dtype=np.float64),
           'depths': np.asarray(rec['depths_m'], dtype=np.float64),
           'forces': np.asarray(rec['forces_N'], dtype=np.float32).reshape(-1, 3),
           'meta': np.array(json.dumps(meta))}
    if disp:
        out['rho'] = np.asarray(disp['rho_m'], dtype=np.float64)
        out['coeffs'] = np.asarray(disp['coeffs_m'], dtype=np.float32)
        out['truncation_rms'] = np.asarray(disp['truncation_rms_m'], dtype=np.float32)
    return out


def arrays_to_record(a: dict[str, np.ndarray]) -> dict[str, Any]:
    """The sweep record (JSON-like dict, as ``sweep.records_to_dataset`` reads) of a point file."""
    meta = json.loads(str(a['meta']))
    dmeta = meta.pop('displacement', {})
    rec: dict[str, Any] = {**meta, 'surface_point_m': a['surface_point'].tolist(),
                           'direction': a['direction'].tolist(), 'depths_m': a['depths'].tolist(),
                           'forces_N': a['forces'].astype(np.float64).tolist()}
    rec.setdefault('status', 'ok')
    if 'coeffs' in a:
        rec['displacement'] = {**dmeta, 'rho_m': a['rho'].tolist(),
                               'coeffs_m': a['coeffs'].astype(np.float64).tolist(),
                               'truncation_rms_m': a['truncation_rms'].astype(np.float64).tolist()}
    return rec
