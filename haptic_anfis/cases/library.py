"""The case library: which cases exist, where their files are, lookup and random draw.

A case is a scene file ``<scenes>/<name>.yaml`` (:mod:`haptic_anfis.tissue.scene`, with a one-line
``description``) plus, under ``<data>/cases/<name>/``, its FE force dataset ``forces.csv`` (+ the
JSON sidecar ``forces.json``) and its trained model ``model.json``, and the contact surface mesh of
its breast size, ``<data>/cases/surface_<Rx>x<Ry>x<Rz>mm.stl`` (STL, in **millimetres**, the unit
the contact detector's ``mesh_unit`` default expects; cases of one size share it).

The case ``default`` is the default scene (``config/scenes/default.yaml``) with the package's
default files (``default_forces.csv``, ``default_model.json``, ``default_surface.stl``), so choosing
no case changes nothing. Pure Python, no ROS.
"""
from __future__ import annotations

import json
import os
import random
import re
from dataclasses import dataclass
from functools import cached_property
from pathlib import Path

from ..errors import HapticAnfisError
from ..tissue.dataset import DATA_DIR, sidecar_path
from ..tissue.scene import SCENE_DIR, Scene, SceneError, load_scene
from ..tissue.store import default_store_root, failed_records, failure_summary
from .background import regrade_background
from .grading import below_device, regrade

DEFAULT_CASE = 'default'
#: the environment variable naming the user's own case folder (``--case-dir`` sets it, so the
#: nodes a command starts see the same cases)
CASE_DIR_ENV = 'HAPTIC_ANFIS_CASE_DIR'
#: radii of the default scene's breast [mm]: its surface is the package's default_surface.stl
_DEFAULT_RADII_MM = (45, 70, 70)
_NAME = re.compile(r'^[a-z0-9][a-z0-9_-]{0,63}$')


class CaseError(HapticAnfisError, ValueError):
    """A case name is unknown, or a case lacks a file it needs; the message names the case and
    the field (scene, dataset_path, model_path, mesh_path)."""


@dataclass(frozen=True)
class Case:
    """One case's files (absolute paths). ``scene`` loads and validates the scene file."""

    name: str
    scene_path: Path
    dataset_path: Path
    model_path: Path
    mesh_path: Path
    work_dir: Path

    @cached_property
    def scene(self) -> Scene:
        try:
            return load_scene(self.scene_path)
        except SceneError as exc:
            raise CaseError(f'case {self.name!r}: scene {str(self.scene_path)!r}: {exc}') from None

    @property
    def description(self) -> str:
        return self.scene.description

    def missing(self, fields: tuple[str, ...] = ('dataset_path', 'model_path', 'mesh_path')
                ) -> list[str]:
        """The fields among ``fields`` whose file does not exist."""
        return [f for f in fields if not getattr(self, f).is_file()]

    def require(self, fields: tuple[str, ...] = ('model_path', 'mesh_path')) -> 'Case':
        """Self if the files of ``fields`` exist (and the scene is valid, and the model was made
        from the scene file as it is now); else a CaseError."""
        _ = self.scene
        gone = self.missing(fields)
        if gone:
            failed = self.fe_failures()
            if failed:  # the builder refuses a case with a hole: generating it cannot succeed
                key, rec = next(iter(failed.items()))
                raise CaseError(
                    f'case {self.name!r} is not ready: its FE point {key} did not solve '
                    f'({failure_summary(str(rec.get("error", "failed")))}; {len(failed)} such '
                    f'point(s)), and a case with a hole in its FE is never built, so `haptic-anfis '
                    f'cases generate {self.name}` refuses it too; choose a ready case '
                    '(`haptic-anfis cases list`)')
            what = ', '.join(f'{f} {str(getattr(self, f))!r}' for f in gone)
            raise CaseError(f'case {self.name!r}: missing {what}; make it with '
                            f'`haptic-anfis cases generate {self.name}`')
        changed = self.scene_changed() if 'model_path' in fields else None
        if changed:
            raise CaseError(changed)
        return self

    def fe_failures(self) -> dict[str, dict]:
        """{point key: failure record} of this graded case's FE points whose every attempt
        failed in the committed store (its own points, then its lesion-free twin's as
        ``twin/<key>``); {} for a case not built from the store (no lesion rings in its
        loading)."""
        scene = self.scene
        if not scene.ring_diameters:
            return {}
        root = default_store_root()
        out = failed_records(root / (scene.fe_store or self.name))
        out.update({f'twin/{k}': r for k, r in failed_records(root / self.name / 'twin').items()})
        return out

    def scene_changed(self) -> str | None:
        """One line saying the case's model or FE grading was made from another version of its
        scene file (a lesion moved, resized or renamed since: the force model would render the
        lumps where they were while the exam scores them where the file puts them now); None
        when they match, or record no scene hash."""
        now = self.scene.sha256()
        case = _json_file(self.model_path).get('case')
        made = {'model': case.get('scene_sha256') if isinstance(case, dict) else None,
                'FE dataset': self._sidecar().get('scene_sha256')}
        for what, h in made.items():
            if isinstance(h, str) and h != now:
                return (f'case {self.name!r}: its scene file {str(self.scene_path)!r} changed '
                        f'since its {what} was made (the lumps rendered and graded would not be '
                        f'those scored); regenerate it with `haptic-anfis cases generate '
                        f'{self.name}`')
        return None

    def _sidecar(self) -> dict:
        """The dataset's provenance sidecar ({} without one)."""
        return _json_file(sidecar_path(self.dataset_path))

    def grading(self, threshold_pct: float | None = None) -> dict | None:
        """The FE grading of a graded-library case (:mod:`.grading`, written by
        :func:`.build.build_case` into the dataset sidecar): ``level``, ``lesions`` (each with
        its per-depth ``contrasts``, ``palpable``, ``found_level``, ``difficulty``, ``reason``),
        ``threshold_pct``; graded again at ``threshold_pct`` [%] when given (a trainee's own
        threshold); None for a case not built from the per-point store, or graded on another
        version of its scene file (:meth:`scene_changed`)."""
        d = self._sidecar()
        if d.get('scene_sha256') not in (None, self.scene.sha256()):
            return None
        g = d.get('grading')
        if g is None or threshold_pct is None:
            return g
        out = regrade(g, threshold_pct)
        if g.get('background') is not None:   # a nodular breast: told apart from its background
            bg = regrade_background(g['background'], threshold_pct)
            out.update(level=bg['level'], background=bg)
        return out

    @property
    def level(self) -> int | None:
        """Difficulty level 1 (easy) .. 5 (hard) from the FE (:mod:`.grading`); None when the case
        is not graded."""
        return self.level_at(None)

    def level_at(self, threshold_pct: float | None) -> int | None:
        """:attr:`level` with the lesions graded at ``threshold_pct`` [%] (None: as stored);
        None too when every lesion is below what the device renders (:meth:`below_device_at`)."""
        g = self.grading(threshold_pct)
        return None if g is None or g.get('level') is None else int(g['level'])

    def below_device_at(self, threshold_pct: float | None = None) -> bool:
        """Whether the case has lesions and, graded at ``threshold_pct`` [%] (None: as stored),
        the device renders none of them: it has no level and is not drawn blind
        (:func:`.grading.below_device`); False for an ungraded case."""
        return below_device(self.grading(threshold_pct))

    def lesions_m(self) -> list[tuple[float, float, float, float]]:
        """(x, y, z, radius) [m] of every lesion, tissue frame."""
        return [(*t.centre, t.radius) for t in self.scene.tumours]


def _json_file(path: Path) -> dict:
    """A generated JSON file's mapping; {} when it is missing or unreadable (its own loader names
    a malformed file)."""
    try:
        d = json.loads(path.read_text())
    except (OSError, ValueError):
        return {}
    return d if isinstance(d, dict) else {}


def surface_file_name(radii_m: tuple[float, float, float]) -> str:
    """'surface_45x70x70mm.stl' for radii (0.045, 0.07, 0.07) m."""
    mm = [round(r * 1e3, 3) for r in radii_m]
    return 'surface_' + 'x'.join(f'{v:g}' for v in mm) + 'mm.stl'


def user_case_dir() -> Path:
    """The user's own case folder: ``$HAPTIC_ANFIS_CASE_DIR``, else
    ``$XDG_DATA_HOME/haptic_anfis/cases`` (``~/.local/share`` when unset). Its layout: a scene
    file ``<dir>/<name>.yaml`` per case and, made by ``cases generate``, the case's files in
    ``<dir>/cases/<name>/`` (as the package's ``data/cases``); it need not exist."""
    env = os.environ.get(CASE_DIR_ENV)
    if env:
        return Path(env).expanduser()
    base = os.environ.get('XDG_DATA_HOME') or str(Path.home() / '.local' / 'share')
    return Path(base) / 'haptic_anfis' / 'cases'


def use_case_dir(path: str | os.PathLike | None) -> Path | None:
    """``--case-dir PATH``: the user's case folder for this process and every node it starts
    (:data:`CASE_DIR_ENV`, absolute); None (nothing changed) without one.

    Raises:
        CaseError: ``path`` exists and is not a folder.
    """
    if not path:
        return None
    p = Path(path).expanduser().resolve()
    if p.exists() and not p.is_dir():
        raise CaseError(f'--case-dir {str(path)!r}: expected a folder of scene files, got a file')
    os.environ[CASE_DIR_ENV] = str(p)
    return p


#: ``--case-dir``'s help, wherever a command takes it
CASE_DIR_HELP = ("a folder of one's own cases (scene files; cases generate writes their files "
                 f"there) beside the package's (default ${CASE_DIR_ENV}, else "
                 '$XDG_DATA_HOME/haptic_anfis/cases)')


def add_case_dir_argument(parser) -> None:
    """``--case-dir DIR`` (the user's own cases, beside the package's)."""
    parser.add_argument('--case-dir', default=None, metavar='DIR', help=CASE_DIR_HELP)


class CaseLibrary:
    """Cases found in ``scene_dir`` (one YAML file each) with files under ``data_dir``, and the
    user's own in ``user_dir`` (:func:`user_case_dir`; scene files there, their files under
    ``user_dir/cases``). A user's case named as a package case is not seen (the package's
    wins, so a shipped name always means the shipped case; ``cases list`` says so).

    Args:
        scene_dir: directory of scene files (default: the package's ``config/scenes``).
        data_dir: the package data directory (default ``haptic_anfis/data``); case files live in
            its ``cases/`` sub-directory, the default case's files in it directly.
        work_root: per-case FE work directories for resuming sweeps (default ``.fe_work/cases``
            in the current directory).
    """

    def __init__(self, scene_dir: str | os.PathLike = SCENE_DIR,
                 data_dir: str | os.PathLike = DATA_DIR,
                 work_root: str | os.PathLike | None = None,
                 user_dir: str | os.PathLike | None = None) -> None:
        self.scene_dir = Path(scene_dir).resolve()
        self.data_dir = Path(data_dir).resolve()
        self.case_dir = self.data_dir / 'cases'
        self.work_root = Path(work_root if work_root is not None
                              else Path('.fe_work') / 'cases').resolve()
        #: a surface of the default breast's size from elsewhere (the user's cases use the
        #: package's), when ``data_dir`` has none
        self.default_surface: Path | None = None
        self.user = (CaseLibrary(user_dir, user_dir, work_root)
                     if user_dir is not None and Path(user_dir).resolve() != self.scene_dir
                     else None)
        if self.user is not None:
            self.user.default_surface = self.data_dir / 'default_surface.stl'

    def _own_names(self) -> list[str]:
        return sorted(p.stem for p in self.scene_dir.glob('*.yaml') if _NAME.match(p.stem))

    def user_names(self) -> list[str]:
        """The user's own cases (:func:`user_case_dir`) this library takes, sorted."""
        if self.user is None:
            return []
        mine = set(self._own_names())
        return [n for n in self.user._own_names() if n not in mine]

    def shadowed(self) -> list[str]:
        """The user's cases not taken because a package case has their name."""
        if self.user is None:
            return []
        return sorted(set(self.user._own_names()) & set(self._own_names()))

    def names(self) -> list[str]:
        """Every case name (scene file stems; the user's after the package's), ``default``
        first."""
        names = sorted(self._own_names(), key=lambda n: n != DEFAULT_CASE)
        return names + self.user_names()

    def get(self, name: str) -> Case:
        """The case called ``name`` (its files need not exist yet: see :meth:`Case.require`)."""
        if not isinstance(name, str) or not _NAME.match(name):
            raise CaseError(f'case name {name!r}: expected lower-case letters, digits, _ or -')
        scene_path = self.scene_dir / f'{name}.yaml'
        if not scene_path.is_file() and name in self.user_names():
            return self.user.get(name)
        if not scene_path.is_file():
            where = (f'; own cases are read from {str(self.user.scene_dir)!r}'
                     if self.user is not None else '')
            raise CaseError(f'unknown case {name!r} (no scene file {str(scene_path)!r}{where}); '
                            f'known cases: {", ".join(self.names()) or "none"}')
        work = self.work_root / name
        if name == DEFAULT_CASE:
            return Case(name, scene_path, self.data_dir / 'default_forces.csv',
                        self.data_dir / 'default_model.json',
                        self.data_dir / 'default_surface.stl', work)
        d = self.case_dir / name
        case = Case(name, scene_path, d / 'forces.csv', d / 'model.json', d / 'surface.stl', work)
        radii = case.scene.radii
        if tuple(round(r * 1e3, 6) for r in radii) == _DEFAULT_RADII_MM:
            mesh = self.data_dir / 'default_surface.stl'
            if not mesh.is_file() and self.default_surface is not None:
                mesh = self.default_surface   # a user's case: the package's surface
        else:
            mesh = self.case_dir / surface_file_name(radii)
        return Case(name, scene_path, case.dataset_path, case.model_path, mesh, work)

    def cases(self) -> list[Case]:
        return [self.get(n) for n in self.names()]

    def levels(self) -> dict[str, int | None]:
        """{case name: difficulty level 1-5 from the FE (:attr:`Case.level`), None if ungraded}."""
        return {c.name: c.level for c in self.cases()}

    def ready(self) -> list[Case]:
        """Cases whose model and mesh exist and fit their scene file (what a session can
        run)."""
        return [c for c in self.cases()
                if not c.missing(('model_path', 'mesh_path')) and not c.scene_changed()]

    def random(self, seed: int, include_default: bool = True) -> Case:
        """A ready case drawn by ``seed`` (the same seed draws the same case from the same library).

        Raises:
            CaseError: no case is ready.
        """
        pool = [c for c in self.ready() if include_default or c.name != DEFAULT_CASE]
        if not pool:
            raise CaseError('no case has a model and a mesh yet; run `haptic-anfis cases generate`')
        return pool[random.Random(int(seed)).randrange(len(pool))]


def library() -> CaseLibrary:
    """The package's shipped library with the user's own cases (:func:`user_case_dir`)."""
    return CaseLibrary(user_dir=user_case_dir())


def get_case(name: str) -> Case:
    """The shipped case ``name``, with its model and mesh present (else CaseError)."""
    return library().get(name).require()


def random_case(seed: int) -> Case:
    """A shipped, ready case drawn by ``seed``."""
    return library().random(seed)


def resolve_case(case: str = '', random_seed: int = -1) -> Case | None:
    """What a node's ``case`` / ``random_case_seed`` parameters select: a ready case, or None for
    '' with seed < 0 (the node's own path parameters then apply).

    Raises:
        CaseError: unknown case, missing files, or both a name and a seed given.
    """
    if case and random_seed >= 0:
        raise CaseError(f'give a case name ({case!r}) or a random-case seed ({random_seed}), '
                        'not both')
    if random_seed >= 0:
        return random_case(random_seed)
    return get_case(case) if case else None


def add_case_arguments(parser) -> None:
    """``--case NAME`` / ``--random-case --seed N`` for the commands that run the graph."""
    g = parser.add_argument_group('case (haptic-anfis cases list)')
    g.add_argument('--case', default='', metavar='NAME',
                   help='run this case of the library (default: the default scene)')
    g.add_argument('--random-case', action='store_true',
                   help='draw a case with --seed; its name is not shown (for a blind session)')
    g.add_argument('--seed', type=int, default=None, help='seed of --random-case')


def case_node_arguments(args) -> list[str]:
    """ROS arguments (``-p name:=value``) for the nodes from ``--case`` / ``--random-case``,
    checked first (unknown case, missing files, --seed without --random-case: CaseError)."""
    if args.random_case:
        if args.case:
            raise CaseError('give --case NAME or --random-case --seed N, not both')
        if args.seed is None or args.seed < 0:
            raise CaseError(f'--random-case needs --seed N with N >= 0, got {args.seed}')
        random_case(args.seed)  # a ready case exists
        return ['-p', f'random_case_seed:={int(args.seed)}']
    if args.seed is not None:
        raise CaseError('--seed is for --random-case')
    if args.case:
        get_case(args.case)
        return ['-p', f'case:={args.case}']
    return []
