"""Put a page together: the skin, coverage grid and dent model of a case, and the debrief of a
recorded bag (no ROS).
"""
from __future__ import annotations

import os
import time

import numpy as np

from ..cases import DEFAULT_CASE, library
from ..contact import load_mesh
from ..exam.config import load_exam_config
from ..exam.from_bag import resolve_exam_case, session_from_bag
from ..exam.lesions import subject_from_scene
from ..exam.session import ExamSession, Surface
from ..tissue.dent_display import dent_model
from ..tissue.displacement import DisplacementDataError
from .app import ViewApp, check_port
from .debrief import Debrief

__all__ = ['CaseView', 'bag_debrief', 'case_view', 'open_bag_view', 'serve']


class CaseView:
    """What the page needs of a case: ``name`` (None = the default scene), skin ``vertices``
    (v, 3) [m] and ``faces``, a fresh exam session (its coverage grid names the region faces),
    the exam config and the dent model (or None)."""

    def __init__(self, name, vertices, faces, session, config, deformation) -> None:
        self.name, self.vertices, self.faces = name, vertices, faces
        self.session, self.config, self.deformation = session, config, deformation

    @property
    def region_faces(self) -> np.ndarray:
        return self.session.grid.faces_index


def _deformation(case):
    """The case's dent model from its FE skin displacements (None, said why, when it has none)."""
    try:   # 5 probe radii, as the visualizer's default dent_reach
        return dent_model(case.dataset_path if case is not None else '', reach=5.0)
    except (DisplacementDataError, OSError, ValueError) as exc:
        print(f'view: no dent drawn ({exc})', flush=True)
        return None


def case_view(case: str | None = None, exam_config: str | os.PathLike | None = None,
              dent: bool = True) -> CaseView:
    """The page's material for ``case`` (a library case name, a scene file, or None).

    Raises:
        CaseError (a ValueError): unknown case (the message lists the known ones).
    """
    cfg = load_exam_config(exam_config)
    c, scene = resolve_exam_case(case, need=('mesh_path',))
    mesh = load_mesh(c.mesh_path if c else library().get(DEFAULT_CASE).mesh_path, unit='mm')
    mesh.merge_vertices()
    session = ExamSession(Surface.from_mesh(mesh), subject_from_scene(scene), cfg)
    deformation = _deformation(c) if dent else None
    return CaseView(c.name if c else None, np.asarray(mesh.vertices, float),
                    np.asarray(mesh.faces, np.int64), session, cfg, deformation)


def bag_debrief(bag: str | os.PathLike, case: str | None = None,
                exam_config: str | os.PathLike | None = None):
    """The :class:`~haptic_anfis.view.debrief.Debrief` of a recorded session (scored as ``exam
    report`` scores it).

    Raises:
        BagError (a ValueError): missing / corrupt bag, or no contact topic in it.
    """
    report, session = session_from_bag(bag, case, exam_config, require_contact=True)
    return Debrief(report, session)


def open_bag_view(bag, case: str | None = None, port: int = 8080, host: str = '127.0.0.1',
                  exam_config=None, trainee: str = '', db=None) -> ViewApp:
    """A page showing the debrief of ``bag`` (checks the port, then the bag, then serves)."""
    check_port(port, host)   # before the seconds of reading the bag
    d = bag_debrief(bag, case, exam_config)
    s = d.session
    app = ViewApp(s.surface.vertices, s.surface.faces, s.grid.faces_index,
                  s.config.thresholds, port=port, host=host,
                  title=f'haptic_anfis debrief: {os.path.basename(str(bag).rstrip("/"))}')
    app.show_debrief(d, trainee, db)
    return app


def serve(app: ViewApp, duration: float | None = None) -> None:
    """Keep serving until Ctrl-C (or ``duration`` s), then close the server."""
    try:
        end = None if duration is None else time.monotonic() + duration
        while end is None or time.monotonic() < end:
            time.sleep(0.2)
    except KeyboardInterrupt:
        pass
    finally:
        app.close()
