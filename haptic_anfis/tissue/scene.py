"""Tissue scenes: breast geometry, tumours, materials, probe and loading protocol.

A scene is a YAML file (see ``config/scenes/default.yaml``). Lengths are millimetres and moduli
kilopascals at that edge, as people write them; :func:`load_scene` converts everything to SI
(m, Pa) and validates it, raising :class:`SceneError` with the offending key named.

Frame (same as :mod:`haptic_anfis.tissue.synthetic`): the chest wall is the plane x = 0, +x points out
of the body, the breast is the semi-ellipsoid (x/Rx)^2 + (y/Ry)^2 + (z/Rz)^2 <= 1, x >= 0.
"""
from __future__ import annotations

import hashlib
import json
import os
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from ..resources import config_dir
from .background import Background, parse_background
from .scenebase import (KPA, MM, SceneError, check_keys, check_number as _num,
                        check_vec as _vec, region_centre, sphere_inside, surface_height)

SCENE_DIR = config_dir('scenes')  # source tree or installed share dir (resources)
DEFAULT_SCENE = SCENE_DIR / 'default.yaml'


@dataclass(frozen=True)
class Tumour:
    """A spherical inclusion. centre (3,) [m] in the tissue frame, radius [m], Young's modulus [Pa]."""

    name: str
    centre: tuple[float, float, float]
    radius: float
    youngs: float
    source: str = ''
    kind: str = ''  # 'malignant' / 'benign' (a label: the FE sees only the modulus); '' = unstated


@dataclass(frozen=True)
class Material:
    """Nearly incompressible Neo-Hookean tissue: Young's modulus [Pa] (small strain), Poisson's ratio."""

    youngs: float
    poisson: float
    source: str = ''

    @property
    def shear(self) -> float:
        """Shear modulus mu = E / (2 (1 + nu)) [Pa]."""
        return self.youngs / (2.0 * (1.0 + self.poisson))

    def bulk_ratio(self) -> float:
        """K / mu for this Poisson's ratio (the same ratio is used for every region)."""
        nu = self.poisson
        return 2.0 * (1.0 + nu) / (3.0 * (1.0 - 2.0 * nu))


@dataclass(frozen=True)
class MeshSettings:
    """Structured hexahedral mesh density.

    probe_cells: cells across the probe footprint (4 * probe_cells nodes lie on its rim);
    the element size along the probe edge is about pi * a / (2 * probe_cells); ``edge_refine``
    halvings of the radial and depth size grade the cells towards the edge singularity;
    ``edge_offset`` pulls the meshed footprint outline that fraction of the first outer cell
    inside the probe radius (the O(h) edge correction, see ``mesh.build_mesh``).
    """

    probe_cells: int = 6
    coarse_probe_cells: int = 4
    edge_refine: int = 1
    rim: float = 0.99
    edge_offset: float = 0.0


@dataclass(frozen=True)
class Scene:
    """A validated scene in SI units. See the module docstring for the frame."""

    name: str
    radii: tuple[float, float, float]
    material: Material
    tumours: tuple[Tumour, ...]
    probe_radius: float
    direction: str
    spacing: float
    palpable_radius: float
    depths: tuple[float, ...]
    max_step: float
    mesh: MeshSettings = field(default_factory=MeshSettings)
    source_sha256: str = ''
    description: str = ''
    #: loading-point refinement near lesions: extra points on a (y, z) grid of this spacing [m]
    #: within lesion radius + ``refine_margin`` [m] of each lesion's (y, z); 0 = none
    refine_spacing: float = 0.0
    refine_margin: float = 0.0
    #: loading-point rings around each lesion: ring radii in lesion DIAMETERS (e.g. (0.5, 1, 1.5)),
    #: ``ring_points`` points on each, plus the centre and its mirror point; () = none
    ring_diameters: tuple[float, ...] = ()
    ring_points: int = 0
    #: the case whose per-point FE store this scene reads (its FE problem is the same: see
    #: :meth:`fe_sha256`); '' = its own (haptic_anfis.cases.sweeps.case_stores)
    fe_store: str = ''
    #: the normal background (nodules, ribs: :mod:`.background`); None = a smooth dome on a flat
    #: chest wall
    background: Background | None = None

    @property
    def graded(self) -> bool:
        """A graded-library scene (solved point by point into the FE store, built with gates):
        one with lesion rings, or with a normal background."""
        return bool(self.ring_diameters) or self.background is not None

    def to_dict(self) -> dict[str, Any]:
        """Plain-dict form in SI units (for provenance sidecars)."""
        return asdict(self)

    def sha256(self) -> str:
        """Hash of the validated SI content (stable across YAML formatting).

        Labels that do not change the FE data (description, lesion kinds) are left out, and so
        are fields added after the shipped default data while they hold their defaults: the
        default scene's hash, recorded in its dataset, stays what it was.
        """
        d = self.to_dict()
        for key in ('source_sha256', 'description', 'fe_store'):
            d.pop(key)
        for t in d['tumours']:
            t.pop('kind')
        for key in ('refine_spacing', 'refine_margin', 'ring_diameters', 'ring_points',
                    'background'):
            if not d[key]:
                d.pop(key)
        return hashlib.sha256(json.dumps(d, sort_keys=True).encode()).hexdigest()

    def fe_sha256(self) -> str:
        """Hash of the FE problem alone: :meth:`sha256` without the labels (name, sources), so two
        scenes that differ only in name solve to the same points (one store serves both)."""
        d = self.to_dict()
        for key in ('source_sha256', 'description', 'fe_store', 'name'):
            d.pop(key)
        d['material'].pop('source')
        for t in d['tumours']:
            for key in ('kind', 'source', 'name'):
                t.pop(key)
        if d['background'] is None:
            d.pop('background')
        else:
            for key in ('nodule_source', 'rib_source'):
                d['background'].pop(key)
        return hashlib.sha256(json.dumps(d, sort_keys=True).encode()).hexdigest()


_KEYS: dict[str, set[str]] = {
    '': {'name', 'description', 'breast', 'material', 'tumours', 'probe', 'loading', 'mesh',
         'fe_store', 'background'},
    'breast': {'radii_mm'},
    'material': {'model', 'youngs_kPa', 'poisson', 'source'},
    'tumour': {'name', 'kind', 'centre_mm', 'position_mm', 'depth_mm', 'radius_mm', 'youngs_kPa',
               'source'},
    'probe': {'diameter_mm', 'direction'},
    'loading': {'spacing_mm', 'palpable_radius_mm', 'depths_mm', 'max_step_mm',
                'refine_spacing_mm', 'refine_margin_mm', 'ring_diameters', 'ring_points'},
    'mesh': {'probe_cells', 'coarse_probe_cells', 'edge_refine', 'rim', 'edge_offset'},
}


def _check_keys(d: Any, section: str, where: str) -> dict[str, Any]:
    return check_keys(d, _KEYS[section], where)


def parse_scene(data: Any, name: str = 'scene', source_sha256: str = '') -> Scene:
    """Validate a scene mapping (YAML units: mm, kPa) and return it in SI units."""
    top = _check_keys(data, '', name)
    for req in ('breast', 'material', 'probe', 'loading'):
        if req not in top:
            raise SceneError(f'{name}: missing required section {req!r}')
    breast = _check_keys(top['breast'], 'breast', 'breast')
    radii = tuple(r * MM for r in _vec(breast, 'radii_mm', 'breast', 3))
    if min(radii) <= 0:
        raise SceneError(f'breast.radii_mm: radii must be > 0, got {breast["radii_mm"]!r}')

    mat = _check_keys(top['material'], 'material', 'material')
    if mat.get('model', 'neo_hookean') != 'neo_hookean':
        raise SceneError(f"material.model: only 'neo_hookean' is supported, got {mat['model']!r}")
    nu = _num(mat, 'poisson', 'material', default=0.499)
    if not 0.0 < nu < 0.5:
        raise SceneError(f'material.poisson: must be in (0, 0.5) (nearly incompressible: '
                         f'0.49-0.4999), got {nu!r}')
    material = Material(youngs=_num(mat, 'youngs_kPa', 'material') * KPA, poisson=nu,
                        source=str(mat.get('source', '')))

    probe = _check_keys(top['probe'], 'probe', 'probe')
    a = 0.5 * _num(probe, 'diameter_mm', 'probe') * MM
    direction = probe.get('direction', 'axis')
    if direction not in ('axis', 'normal'):
        raise SceneError(f"probe.direction: expected 'axis' (along -x, perpendicular to the body) "
                         f"or 'normal' (local surface normal), got {direction!r}")

    load = _check_keys(top['loading'], 'loading', 'loading')
    spacing = _num(load, 'spacing_mm', 'loading') * MM
    palp = _num(load, 'palpable_radius_mm', 'loading') * MM
    max_step = _num(load, 'max_step_mm', 'loading', default=2.0) * MM
    depths_raw = load.get('depths_mm')
    if (not isinstance(depths_raw, (list, tuple)) or not depths_raw
            or not all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in depths_raw)):
        raise SceneError(f'loading.depths_mm: expected a non-empty list of numbers, got {depths_raw!r}')
    depths = tuple(float(v) * MM for v in depths_raw)
    if any(d <= 0 for d in depths) or any(np.diff(depths) <= 0):
        raise SceneError(f'loading.depths_mm: depths must be > 0 and strictly increasing, '
                         f'got {depths_raw!r}')

    mesh_d = _check_keys(top.get('mesh', {}) or {}, 'mesh', 'mesh')
    mesh = MeshSettings(probe_cells=int(_num(mesh_d, 'probe_cells', 'mesh', default=10)),
                        coarse_probe_cells=int(_num(mesh_d, 'coarse_probe_cells', 'mesh', default=4)),
                        edge_refine=int(_num(mesh_d, 'edge_refine', 'mesh', positive=False,
                                             default=1)),
                        rim=_num(mesh_d, 'rim', 'mesh', default=0.99),
                        edge_offset=_num(mesh_d, 'edge_offset', 'mesh', positive=False,
                                         default=0.0))
    if mesh.probe_cells < 2 or mesh.coarse_probe_cells < 2:
        raise SceneError('mesh.probe_cells / coarse_probe_cells: need at least 2')
    if not 0 <= mesh.edge_refine <= 4:
        raise SceneError(f'mesh.edge_refine: 0 .. 4 halvings, got {mesh.edge_refine!r}')
    if not 0.0 <= mesh.edge_offset < 1.0:
        raise SceneError(f'mesh.edge_offset: fraction of the first cell outside the probe edge, '
                         f'in [0, 1), got {mesh.edge_offset!r}')
    if not 0.5 < mesh.rim < 1.0:
        raise SceneError(f'mesh.rim: fraction of the base radius that is meshed, in (0.5, 1), '
                         f'got {mesh.rim!r}')

    # The probe footprint must stay on tissue: the palpable disc plus the probe radius must fit
    # inside the meshed base ellipse.
    rmin = min(radii[1], radii[2]) * mesh.rim
    if palp + a >= rmin:
        raise SceneError(f'loading.palpable_radius_mm: {palp / MM:g} mm plus the probe radius '
                         f'{a / MM:g} mm reaches the edge of the breast ({rmin / MM:.1f} mm)')
    # Depth beyond thickness: the deepest indentation must leave tissue under the probe.
    thinnest = float(surface_height(np.array(palp), np.array(0.0),
                                    (radii[0], rmin / mesh.rim, rmin / mesh.rim)))
    if depths[-1] >= 0.8 * thinnest:
        raise SceneError(f'loading.depths_mm: deepest indentation {depths[-1] / MM:g} mm is beyond '
                         f'80 % of the tissue thickness at the palpable edge '
                         f'({thinnest / MM:.1f} mm at {palp / MM:g} mm from the centre)')

    tumours = _parse_lesions(top.get('tumours', []) or [], radii, str(top.get('name', name)))
    refine_spacing = _num(load, 'refine_spacing_mm', 'loading', positive=False, default=0.0) * MM
    refine_margin = _num(load, 'refine_margin_mm', 'loading', positive=False, default=0.0) * MM
    if refine_spacing < 0 or refine_margin < 0 or (refine_spacing > 0) != (refine_margin > 0):
        raise SceneError(f'loading.refine_spacing_mm / refine_margin_mm: both > 0 (extra loading '
                         f'points near lesions) or both 0, got {refine_spacing / MM:g} / '
                         f'{refine_margin / MM:g}')
    if refine_spacing >= spacing:
        raise SceneError(f'loading.refine_spacing_mm: {refine_spacing / MM:g} mm must be finer '
                         f'than spacing_mm ({spacing / MM:g} mm)')
    rings_raw = load.get('ring_diameters', []) or []
    if (not isinstance(rings_raw, (list, tuple))
            or not all(isinstance(v, (int, float)) and not isinstance(v, bool) and 0 < v <= 3
                       for v in rings_raw)
            or any(np.diff(rings_raw) <= 0)):
        raise SceneError(f'loading.ring_diameters: expected increasing ring radii in lesion '
                         f'diameters, each in (0, 3], got {rings_raw!r}')
    ring_points = load.get('ring_points', 8 if rings_raw else 0)
    if isinstance(ring_points, bool) or not isinstance(ring_points, int) \
            or not (0 <= ring_points <= 64) or (bool(rings_raw) != (ring_points > 0)):
        raise SceneError(f'loading.ring_points: points per lesion ring, 1 to 64 with '
                         f'ring_diameters (0 without), got {ring_points!r}')
    description = top.get('description', '')
    if not isinstance(description, str) or '\n' in description.strip():
        raise SceneError(f'{name}.description: expected one line of text, got {description!r}')
    return Scene(name=str(top.get('name', name)), radii=radii, material=material,
                 tumours=tuple(tumours), probe_radius=a, direction=direction, spacing=spacing,
                 palpable_radius=palp, depths=depths, max_step=max_step, mesh=mesh,
                 source_sha256=source_sha256, description=description.strip(),
                 refine_spacing=refine_spacing, refine_margin=refine_margin,
                 ring_diameters=tuple(float(v) for v in rings_raw), ring_points=int(ring_points),
                 fe_store=_fe_store(top.get('fe_store', ''), name),
                 background=parse_background(top.get('background'), radii, material.youngs,
                                             tumours, palp + a))


def _fe_store(v: Any, where: str) -> str:
    if not isinstance(v, str) or (v and not v.replace('_', '').replace('-', '').isalnum()):
        raise SceneError(f'{where}: fe_store: expected the name of a case (letters, digits, _ and '
                         f'-), got {v!r}')
    return v


#: Lesion limits of the scene format: at most 3 lesions of diameter 5-25 mm (5 mm is what
#: clinical breast-exam training aims to find). A 5 mm lesion spans only a few FE cells (~2 mm
#: under the probe, coarser away from it; its stiffness enters per cell by volume fraction) and a
#: 16 mm probe may not feel it at all: the library decides palpability from the FE.
MAX_LESIONS = 3
LESION_RADIUS_MM = (2.5, 12.5)
LESION_KINDS = ('malignant', 'benign')


def _parse_lesions(items: Any, radii: tuple[float, float, float], scene: str) -> tuple[Tumour, ...]:
    """The ``tumours`` list: each lesion by ``centre_mm`` (x, y, z), or by ``position_mm`` (y, z)
    over the chest wall plus ``depth_mm`` of its centre under the skin (along -x)."""
    if not isinstance(items, list):
        raise SceneError(f'{scene}: tumours: expected a list of lesions, got {type(items).__name__}')
    if len(items) > MAX_LESIONS:
        raise SceneError(f'{scene}: tumours: at most {MAX_LESIONS} lesions, got {len(items)}')
    out: list[Tumour] = []
    for i, t in enumerate(items):
        where = f'{scene}: tumours[{i}]'
        t = _check_keys(t, 'tumour', where)
        c, given = region_centre(t, where, radii)
        r = _num(t, 'radius_mm', where) * MM
        lo, hi = LESION_RADIUS_MM
        if not lo <= r / MM <= hi:
            raise SceneError(f'{where}.radius_mm: expected {lo:g} to {hi:g} mm, got {r / MM:g}')
        e = _num(t, 'youngs_kPa', where) * KPA
        kind = t.get('kind', '')
        if kind not in ('', *LESION_KINDS):
            raise SceneError(f'{where}.kind: expected one of {LESION_KINDS}, got {kind!r}')
        inside = sphere_inside(c, r, radii)
        if not inside:
            raise SceneError(f'{where}: tumour ({given}, radius {t["radius_mm"]} mm) is not inside '
                             'the tissue (it must clear the skin surface and the chest wall x = 0)')
        for j, other in enumerate(out):
            gap = float(np.linalg.norm(np.subtract(c, other.centre))) - r - other.radius
            if gap < 0:
                raise SceneError(f'{where}: overlaps tumours[{j}] ({other.name}) by '
                                 f'{-gap / MM:.1f} mm; lesions must be separate')
        name = str(t.get('name', f'tumour{i}'))
        twin = [j for j, other in enumerate(out) if other.name == name]
        if twin:   # names key the grading, the FE twins and the exam's palpability
            raise SceneError(f'{where}.name: {name!r} is also the name of tumours[{twin[0]}]; '
                             'expected a name of its own for each lesion')
        out.append(Tumour(name=name, centre=c, radius=r, youngs=e,
                          source=str(t.get('source', '')), kind=kind))
    return tuple(out)


def load_scene(path: str | os.PathLike = DEFAULT_SCENE) -> Scene:
    """Read and validate a scene YAML file. Raises SceneError (a ValueError) on any problem."""
    path = Path(path)
    if not path.is_file():
        raise SceneError(f'scene file {str(path)!r} does not exist')
    raw = path.read_bytes()
    try:
        data = yaml.safe_load(raw)
    except yaml.YAMLError as exc:
        raise SceneError(f'scene file {str(path)!r} is not valid YAML: {exc}') from None
    return parse_scene(data, name=path.stem, source_sha256=hashlib.sha256(raw).hexdigest())
