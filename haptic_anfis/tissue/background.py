"""A normal breast's background in a scene: glandular nodules (or fat lobules) and ribs.

A normal breast is not a homogeneous dome: glandular tissue lies in fat as many small firm
regions (clinically "nodularity"), and the ribs lie under it at the chest wall. A scene's optional
``background`` section describes both (YAML units mm / kPa, SI inside):

- ``nodules``: spheres of another modulus than the breast's ``material``: glandular nodules in a
  fatty breast (stiffer) or fat lobules in a dense one (softer). Either ``count`` of them drawn
  with ``seed`` (radius, (y, z) position within ``extent_mm`` of the apex and centre depth under
  the skin uniform in their ranges; none closer than ``min_gap_mm`` to another region), or an
  explicit ``items`` list (``position_mm`` + ``depth_mm`` or ``centre_mm``, ``radius_mm``). The
  drawn list is part of the scene's hash, so the FE store knows the nodules it was solved with.
- ``ribs``: bars along y at the chest wall, at the given ``z_mm``, ``width_mm`` across, rising
  ``height_mm`` above the chest wall plane x = 0 as a half-ellipse (the rest of the bone lies
  behind it, in the clamped wall). A rib keeps ``cover_mm`` of soft tissue
  under the skin over the loaded area (the palpable disc widened by the probe radius), or the scene
  is refused ("a rib through the skin"); towards the clamped rim, where the breast thins to nothing,
  the bar is cut ``cover_mm`` under the skin. Ribs are rigid and take no modulus: the FE's
  clamped wall rises over them (:func:`rib_floor`), so a rib is a boundary every mesh node lies
  on, not a stiffness smeared over the cells it cuts (which made the force depend on the mesh:
  4 -> 6 cells across the probe moved it 23 % at 12 mm over a rib; now 3 %, as in a smooth
  breast).

Every region (lesion, nodule, rib) must lie apart from every other and inside the breast; a scene
that breaks this is refused in one line naming the region.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Sequence

import numpy as np

from .scenebase import (KPA, MM, SceneError, check_keys, check_number, check_vec,
                        region_centre, sphere_inside, surface_height)

__all__ = ['Background', 'Nodule', 'Rib', 'parse_background', 'rib_floor', 'NODULE_RADIUS_MM']

#: nodule radii the format accepts [mm]: below 1 mm a nodule is smaller than any FE cell; above
#: 8 mm it is a lesion's size, not background texture
NODULE_RADIUS_MM = (1.0, 8.0)
MAX_NODULES = 400
_KEYS = {
    'background': {'nodules', 'ribs'},
    'nodules': {'seed', 'count', 'radius_mm', 'depth_mm', 'extent_mm', 'min_gap_mm', 'youngs_kPa',
                'source', 'items'},
    'item': {'name', 'position_mm', 'depth_mm', 'centre_mm', 'radius_mm'},
    'ribs': {'z_mm', 'width_mm', 'height_mm', 'cover_mm', 'source'},
}


@dataclass(frozen=True)
class Nodule:
    """A normal-tissue sphere: centre (3,) [m] in the tissue frame, radius [m], modulus [Pa];
    kind 'glandular' (stiffer than the breast around it) or 'fat' (softer)."""

    name: str
    centre: tuple[float, float, float]
    radius: float
    youngs: float
    kind: str

    @property
    def what(self) -> str:
        """What it is, as the exam says it to the trainee."""
        return 'a normal glandular lobule' if self.kind == 'glandular' else 'a fat lobule'


@dataclass(frozen=True)
class Rib:
    """A rigid bar along y at ``z`` [m], ``radius`` [m] half its width, rising ``top`` [m] above
    the chest wall as a half-ellipse; ``cover`` [m] of tissue it keeps under the skin. Bone (~GPa)
    is rigid against tissue (~20 kPa): the FE makes the clamped wall follow it
    (:func:`rib_floor`)."""

    name: str
    z: float
    radius: float
    top: float
    cover: float
    #: how the FE represents it; part of the scene's hash, so a store knows its ribs' model
    profile: str = 'rigid half-ellipse'

    #: what it is, as the exam says it to the trainee
    what = 'a rib'

    def rise(self, z: np.ndarray) -> np.ndarray:
        """Height [m] of its surface above the chest wall at ``z`` [m] (0 beside it)."""
        u = (np.asarray(z, dtype=float) - self.z) / self.radius
        return self.top * np.sqrt(np.clip(1.0 - u * u, 0.0, None))


@dataclass(frozen=True)
class Background:
    """The validated background in SI units; ``seed`` None for an explicit nodule list."""

    nodules: tuple[Nodule, ...] = ()
    ribs: tuple[Rib, ...] = ()
    seed: int | None = None
    nodule_source: str = ''
    rib_source: str = ''

    @property
    def kind(self) -> str:
        """'nodular' with nodules, else 'smooth'."""
        return 'nodular' if self.nodules else 'smooth'

    def region_at(self, y: float, z: float, margin: float = 0.0) -> tuple[str, str] | None:
        """(name, what it is) of the normal region under the skin point over (y, z) [m]: the
        nearest nodule whose (y, z) lies within its radius + ``margin`` [m] ('a normal glandular
        lobule' / 'a fat lobule'), else a rib whose line lies within its half width + ``margin``
        ('a rib'); None when the point is over neither. (What a false mark there was on.)"""
        best, bd = None, np.inf
        for n in self.nodules:
            d = float(np.hypot(y - n.centre[1], z - n.centre[2]))
            if d <= n.radius + margin and d < bd:
                best, bd = n, d
        if best is not None:
            return best.name, best.what
        for rib in self.ribs:
            if abs(z - rib.z) <= rib.radius + margin:
                return rib.name, rib.what
        return None


def _keys(d: Any, section: str, where: str) -> dict[str, Any]:
    return check_keys(d, _KEYS[section], where)


def _range(d: dict[str, Any], key: str, where: str) -> tuple[float, float]:
    lo, hi = check_vec(d, key, where, 2)
    if not 0 < lo <= hi:
        raise SceneError(f'{where}.{key}: expected [low, high] with 0 < low <= high, '
                         f'got {d[key]!r}')
    return lo * MM, hi * MM


def _source(d: dict[str, Any], where: str) -> str:
    s = d.get('source', '')
    if not isinstance(s, str) or not s.strip():
        raise SceneError(f'{where}.source: expected the paper or page the figures come from '
                         f'(one line), got {s!r}')
    return s.strip()


def parse_background(data: Any, radii: tuple[float, float, float], youngs: float,
                     lesions: Sequence[Any], loaded_radius: float) -> Background | None:
    """The ``background`` section (or None when absent), validated against the breast ``radii``
    [m], the breast's modulus ``youngs`` [Pa] (a nodule's kind), the scene's ``lesions`` (objects
    with name, centre, radius) and the loaded area's radius [m] (palpable disc + probe)."""
    if data is None:
        return None
    bg = _keys(data, 'background', 'background')
    ribs = _parse_ribs(bg['ribs'], radii, loaded_radius) if bg.get('ribs') else ()
    for i, rib in enumerate(ribs):
        for j, t in enumerate(lesions):
            gap = _rib_gap(rib, np.asarray(t.centre), t.radius)
            if gap < 0:
                raise SceneError(f'background.ribs[{i}] (z = {rib.z / MM:g} mm): overlaps '
                                 f'tumours[{j}] ({t.name}) by {-gap / MM:.1f} mm')
    nodules, seed, nsrc = (), None, ''
    if bg.get('nodules'):
        nd = _keys(bg['nodules'], 'nodules', 'background.nodules')
        nsrc = _source(nd, 'background.nodules')
        e = check_number(nd, 'youngs_kPa', 'background.nodules') * KPA
        if abs(e - youngs) < 1e-9 * youngs:
            raise SceneError(f'background.nodules.youngs_kPa: {e / KPA:g} kPa is the breast\'s own '
                             'modulus; a nodule must differ from the tissue around it')
        if ('items' in nd) == ('count' in nd):
            raise SceneError('background.nodules: give either count (drawn with seed) or items '
                             '(an explicit list), not both or neither')
        if 'items' in nd:
            nodules = _explicit(nd, radii, e, youngs)
        else:
            seed = nd.get('seed')
            if isinstance(seed, bool) or not isinstance(seed, int) or seed < 0:
                raise SceneError(f'background.nodules.seed: expected an integer >= 0 (the draw is '
                                 f'reproducible), got {seed!r}')
            nodules = _drawn(nd, radii, e, youngs, seed, lesions, ribs)
        _check_regions(nodules, radii, lesions, ribs)
    return Background(nodules=nodules, ribs=ribs, seed=seed, nodule_source=nsrc,
                      rib_source=_source(bg['ribs'], 'background.ribs') if ribs else '')


def _parse_ribs(d: Any, radii: tuple[float, float, float], loaded_radius: float
                ) -> tuple[Rib, ...]:
    if isinstance(d, dict) and 'youngs_kPa' in d:
        raise SceneError('background.ribs.youngs_kPa: ribs are rigid (the clamped chest wall '
                         'rises over them), they take no modulus: remove the key')
    rd = _keys(d, 'ribs', 'background.ribs')
    zs = rd.get('z_mm')
    if (not isinstance(zs, list) or not zs or not all(
            isinstance(v, (int, float)) and not isinstance(v, bool) and np.isfinite(v)
            for v in zs)):
        raise SceneError(f'background.ribs.z_mm: expected a list of rib positions (z, mm), '
                         f'got {zs!r}')
    r = 0.5 * check_number(rd, 'width_mm', 'background.ribs') * MM
    top = check_number(rd, 'height_mm', 'background.ribs') * MM
    cover = check_number(rd, 'cover_mm', 'background.ribs') * MM
    out: list[Rib] = []
    for i, z in enumerate(sorted(float(v) * MM for v in zs)):
        rib = Rib(name=f'rib{i}', z=z, radius=r, top=top, cover=cover)
        where = f'background.ribs[{i}] (z = {z / MM:g} mm)'
        if abs(z) + r >= radii[2]:
            raise SceneError(f'{where}: lies outside the breast (|z| + half width >= '
                             f'{radii[2] / MM:g} mm)')
        if out and z - out[-1].z < 2 * r:
            raise SceneError(f'{where}: overlaps ribs[{i - 1}] (z = {out[-1].z / MM:g} mm): rib '
                             f'centres must be at least the width {2 * r / MM:g} mm apart')
        # over the loaded area the rib must stay cover_mm under the skin
        half = np.sqrt(max(loaded_radius ** 2 - z ** 2, 0.0))
        if half > 0:
            y = np.linspace(-half, half, 201)
            thick = surface_height(y, np.full_like(y, z), radii)
            k = int(np.argmin(thick))
            if thick[k] - top < cover:
                raise SceneError(f'{where}: a rib through the skin: its top {top / MM:g} mm above '
                                 f'the chest wall leaves {max(thick[k] - top, 0) / MM:.1f} mm of '
                                 f'tissue at y = {y[k] / MM:.0f} mm, less than cover_mm '
                                 f'{cover / MM:g} mm')
        out.append(rib)
    return tuple(out)


def _kind(e: float, youngs: float) -> str:
    return 'glandular' if e > youngs else 'fat'


def _explicit(nd: dict[str, Any], radii, e: float, youngs: float) -> tuple[Nodule, ...]:
    items = nd['items']
    if not isinstance(items, list) or not items or len(items) > MAX_NODULES:
        raise SceneError(f'background.nodules.items: expected a list of 1 to {MAX_NODULES} '
                         f'nodules, got {items!r}')
    out = []
    for i, t in enumerate(items):
        where = f'background.nodules[{i}]'
        t = _keys(t, 'item', where)
        c, _ = region_centre(t, where, radii)
        r = check_number(t, 'radius_mm', where) * MM
        out.append(Nodule(name=str(t.get('name', f'nodule{i}')), centre=c, radius=r, youngs=e,
                          kind=_kind(e, youngs)))
    return tuple(out)


def _drawn(nd: dict[str, Any], radii, e: float, youngs: float, seed: int, lesions, ribs
           ) -> tuple[Nodule, ...]:
    """``count`` nodules drawn with ``seed`` by rejection: each candidate must lie inside the
    breast and ``min_gap_mm`` from every region placed before it."""
    where = 'background.nodules'
    count = nd.get('count')
    if isinstance(count, bool) or not isinstance(count, int) or not 1 <= count <= MAX_NODULES:
        raise SceneError(f'{where}.count: expected an integer 1 to {MAX_NODULES}, got {count!r}')
    rlo, rhi = _range(nd, 'radius_mm', where)
    dlo, dhi = _range(nd, 'depth_mm', where)
    extent = check_number(nd, 'extent_mm', where) * MM
    gap = check_number(nd, 'min_gap_mm', where, positive=False, default=1.0) * MM
    lo, hi = NODULE_RADIUS_MM
    if rlo < lo * MM or rhi > hi * MM:
        raise SceneError(f'{where}.radius_mm: expected within [{lo:g}, {hi:g}] mm, got '
                         f'{nd["radius_mm"]!r}')
    rng = np.random.default_rng(seed)
    regions = [(np.asarray(t.centre, dtype=float), float(t.radius)) for t in lesions]
    out: list[Nodule] = []
    for _ in range(300 * count):
        if len(out) == count:
            break
        r = rng.uniform(rlo, rhi)
        rho, th = extent * np.sqrt(rng.uniform()), rng.uniform(0.0, 2.0 * np.pi)
        y, z = rho * np.cos(th), rho * np.sin(th)
        top = float(surface_height(np.array(y), np.array(z), radii))
        c = np.array([top - rng.uniform(dlo, dhi), y, z])
        if not sphere_inside(tuple(c), r + gap, radii):
            continue
        if any(np.linalg.norm(c - oc) < r + orad + gap for oc, orad in regions):
            continue
        if any(_rib_gap(rib, c, r) < gap for rib in ribs):
            continue
        regions.append((c, r))
        out.append(Nodule(name=f'nodule{len(out)}', centre=tuple(float(v) for v in c), radius=r,
                          youngs=e, kind=_kind(e, youngs)))
    if len(out) < count:
        raise SceneError(f'{where}: placed only {len(out)} of count {count} nodules apart from '
                         f'each other, the lesions and the ribs; lower count or widen extent_mm / '
                         f'depth_mm')
    return tuple(out)


def _rib_gap(rib: Rib, centre: np.ndarray, r: float) -> float:
    """Clearance [m] between a sphere (centre, r) and the rib's half-ellipse (negative: overlap),
    from 721 points of its outline."""
    t = np.linspace(0.0, np.pi, 721)
    d = np.hypot(centre[0] - rib.top * np.sin(t), centre[2] - rib.z - rib.radius * np.cos(t))
    inside = centre[0] < rib.rise(centre[2])
    return float(-d.min() - r if inside else d.min() - r)


def _check_regions(nodules: Sequence[Nodule], radii, lesions, ribs) -> None:
    """Every nodule inside the breast, apart from lesions, ribs and the other nodules."""
    for i, n in enumerate(nodules):
        where = f'background.nodules[{i}] ({n.name})'
        c = np.asarray(n.centre)
        if not NODULE_RADIUS_MM[0] * MM <= n.radius <= NODULE_RADIUS_MM[1] * MM:
            raise SceneError(f'{where}.radius_mm: expected {NODULE_RADIUS_MM[0]:g} to '
                             f'{NODULE_RADIUS_MM[1]:g} mm, got {n.radius / MM:g}')
        if not sphere_inside(n.centre, n.radius, radii):
            raise SceneError(f'{where}: nodule (centre {[round(v / MM, 1) for v in n.centre]} mm, '
                             f'radius {n.radius / MM:g} mm) is outside the breast (it must clear '
                             'the skin and the chest wall x = 0)')
        for j, t in enumerate(lesions):
            gap = float(np.linalg.norm(c - np.asarray(t.centre))) - n.radius - t.radius
            if gap < 0:
                raise SceneError(f'{where}: overlaps tumours[{j}] ({t.name}) by {-gap / MM:.1f} mm')
        for j, rib in enumerate(ribs):
            gap = _rib_gap(rib, c, n.radius)
            if gap < 0:
                raise SceneError(f'{where}: overlaps ribs[{j}] (z = {rib.z / MM:g} mm) by '
                                 f'{-gap / MM:.1f} mm')
        for j, o in enumerate(nodules[:i]):
            gap = float(np.linalg.norm(c - np.asarray(o.centre))) - n.radius - o.radius
            if gap < 0:
                raise SceneError(f'{where}: overlaps background.nodules[{j}] ({o.name}) by '
                                 f'{-gap / MM:.1f} mm')


def rib_floor(y: np.ndarray, z: np.ndarray, ribs: Sequence[Rib], top: np.ndarray) -> np.ndarray:
    """x [m] of the rigid chest wall at (y, z) [m]: the chest-wall plane x = 0 raised by the ribs
    (:meth:`Rib.rise`: continuous, so no cell is torn at a rib's edge), and kept at least
    ``rib.cover`` under the surface ``top`` [m] (where the breast thins towards its clamped rim,
    beyond the loaded area, the rib is lowered with it rather than poking through the skin)."""
    z = np.asarray(z, dtype=float)
    out = np.zeros(np.broadcast(np.asarray(y), z).shape)
    for rib in ribs:
        room = np.clip(np.asarray(top) - rib.cover, 0.0, None)
        out = np.maximum(out, np.minimum(rib.rise(z), room))
    return out
