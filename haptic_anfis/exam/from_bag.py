"""Score a recorded session: a bag's loop topics into an :class:`ExamSession` and its report
(no ROS; ``haptic-anfis exam report`` and the browser view's debrief share it).

Times in seconds (message stamps), lengths in metres.
"""
from __future__ import annotations

import os
from pathlib import Path

from .. import interfaces as ifc
from ..bag.errors import BagError
from ..bag.reader import RECORDER_MARK, bag_info, read_messages
from ..bag.topics import absolute
from ..cases import CaseError, DEFAULT_CASE, library
from ..contact import load_mesh
from ..device.buttons import CLUTCH, MARK
from .config import load_exam_config
from .lesions import subject_from_scene
from .session import ExamSession, Surface

__all__ = ['new_session', 'recorded_case', 'resolve_exam_case', 'session_from_bag']


def resolve_exam_case(case: str | None, need: tuple[str, ...] = ('model_path', 'mesh_path'),
                      lib=None):
    """``--case``: a case of the library (``haptic-anfis cases list``; its files ``need`` must
    exist) or a scene file (``*.yaml``: its lesions are scored, the default model and surface
    render) -> ``(Case | None, scene path | None)``; ``(None, None)`` = the default scene.

    Raises:
        CaseError (a ValueError): unknown case (the message lists the known ones), or a file it
        needs is missing.
    """
    if case is None:
        return None, None
    p = Path(case)
    if p.suffix in ('.yaml', '.yml') and p.is_file():
        return None, str(p)
    c = (lib or library()).get(case).require(need)
    return c, str(c.scene_path)


def recorded_case(bag, custom_data: dict, case: str | None) -> tuple[str | None, str]:
    """``(case to score against, note)`` for ``bag`` with its ``custom_data`` (metadata.yaml):
    ``case`` if given (the note says when the bag was recorded with another), else the scene
    file or the case the package's recorder wrote (``scene``, ``case``; 'default' -> None); a
    bag without them (recorded before the recorder wrote them, or by another recorder, whose
    keys of these names are not ours): None, the default, with a note saying so.

    Raises:
        BagError: no ``case`` given and the bag holds several cases (a session switched them);
            its scene file is gone.
        CaseError: the bag's case is not in this library (or not ready).
    """
    ours = custom_data.get('recorder') == RECORDER_MARK
    scene, recorded = ((custom_data.get('scene', ''), custom_data.get('case', '')) if ours
                       else ('', ''))
    said = f'scene file {scene}' if scene else f'case {recorded}' if recorded else ''
    if case is not None:
        same = case in (recorded, scene) or scene and Path(case).resolve() == Path(scene)
        return case, ('' if not said or same else
                      f'scored against --case {case}; the bag was recorded with {said}')
    if ',' in recorded:   # (with a scene file too: its exam switched case afterwards)
        raise BagError(f'{bag}: the session switched cases while recording ({recorded}): give '
                       '--case NAME to score it against one of them')
    if scene:
        if not Path(scene).is_file():
            raise BagError(f'{bag}: recorded with the scene file {scene}, which is gone: give '
                           '--case (a case or a scene file) to score it')
        return scene, ''
    if not recorded:
        return None, ('the bag does not say which case it was recorded with (a session given '
                      'parameter files or overrides, a recorder started on its own, or an older '
                      'version): scored against the default case; give --case if it was another')
    if recorded == 'default':
        return None, ''
    try:
        library().get(recorded).require(('mesh_path',))
    except CaseError as exc:
        raise CaseError(f'{bag}: recorded with case {recorded}: {exc}') from None
    return recorded, ''


def _new_session(c, subject, cfg) -> ExamSession:
    mesh = load_mesh(c.mesh_path if c else library().get(DEFAULT_CASE).mesh_path, unit='mm')
    mesh.merge_vertices()
    return ExamSession(Surface.from_mesh(mesh), subject, cfg)


def new_session(case: str | None = None, exam_config: str | os.PathLike | None = None
                ) -> ExamSession:
    """An empty :class:`ExamSession` of ``case`` (a library case or a scene file; None = the
    default scene) with the scoring settings ``exam_config`` (None = config/exam.yaml)."""
    c, scene = resolve_exam_case(case, need=('mesh_path',))
    return _new_session(c, subject_from_scene(scene), load_exam_config(exam_config))


def session_from_bag(bag: str | os.PathLike, case: str | None = None,
                     exam_config: str | os.PathLike | None = None,
                     require_contact: bool = False) -> tuple[dict, ExamSession]:
    """``(report, session)`` of the session recorded in ``bag``, scored against ``case`` (a
    library case or a scene file; None = the case the bag says it was recorded with, see
    :func:`recorded_case`) with the scoring settings ``exam_config`` (None = config/exam.yaml).

    The report carries ``notes`` on what the bag lacks (no contact topic: zero coverage; no
    ``exam/marks``: marks from button 1 presses at the probe pose; no case: the default) or
    where ``case`` differs from the bag's, ``bag`` and ``case``.

    Raises:
        BagError (a ValueError): missing or unreadable bag; a bag of several cases and no
        ``case``; or, with ``require_contact``, a bag without the contact topic (the message
        names it and lists the topics it has).
        CaseError / ValueError: unknown case (also one the bag names), bad exam config.
    """
    cfg = load_exam_config(exam_config)
    info = bag_info(bag)   # BagError on a missing / corrupt bag, before the mesh is loaded
    case, case_note = recorded_case(bag, info.custom_data, case)
    c, scene = resolve_exam_case(case, need=('mesh_path',))
    subject = subject_from_scene(scene)
    have = {t.topic for t in info.topics}
    missing = [t for t in (absolute(ifc.TOPIC_CONTACT),) if t not in have]
    if missing and require_contact:
        raise BagError(f'{bag}: no {", ".join(missing)} topic (it has '
                       f'{", ".join(sorted(have)) or "none"}): nothing to show')
    session = _new_session(c, subject, cfg)
    wanted = {absolute(t) for t in (ifc.TOPIC_CONTACT, ifc.TOPIC_COMMAND, ifc.TOPIC_POSE,
                                    ifc.TOPIC_MARKS, ifc.TOPIC_BUTTONS)} & have
    notes = [case_note] if case_note else []
    if missing:
        notes.append(f'{bag}: no {", ".join(missing)} topic (it has '
                     f'{", ".join(sorted(have)) or "none"}): nothing to score, zero coverage')
    marks_topic = absolute(ifc.TOPIC_MARKS) in have
    if not marks_topic:
        notes.append('no exam/marks topic: marks taken from button 1 presses at the probe pose '
                     '(not while the clutch, button 0, is held: the driver marks nothing then)')
    last_pose, mark_prev = None, False
    for topic, _, _, msg in read_messages(bag, sorted(wanted)) if wanted else ():
        t = msg.header.stamp.sec + msg.header.stamp.nanosec * 1e-9
        if topic == absolute(ifc.TOPIC_CONTACT):
            session.add_contact_values(t, msg.position)   # either layout; others counted
        elif topic == absolute(ifc.TOPIC_COMMAND):
            f = msg.wrench.force
            session.add_force(t, (f.x, f.y, f.z))
        elif topic == absolute(ifc.TOPIC_POSE):
            q = msg.pose.position
            last_pose = (q.x, q.y, q.z)
            session.add_pose(t, last_pose)
        elif topic == absolute(ifc.TOPIC_MARKS):
            q = msg.point
            session.add_mark(t, (q.x, q.y, q.z))
        elif topic == absolute(ifc.TOPIC_BUTTONS):
            b = list(msg.buttons)
            session.add_buttons(t, b)
            # the driver's rule (device.buttons): a rising edge of the mark button
            # while the clutch is not held
            mark, clutch = len(b) > MARK and bool(b[MARK]), len(b) > CLUTCH and bool(b[CLUTCH])
            if not marks_topic and mark and not mark_prev and not clutch \
                    and last_pose is not None:
                session.add_mark(t, last_pose)
            mark_prev = mark
    report = session.report()
    report['notes'] = notes + report['notes']
    report['bag'] = str(bag)
    report['case'] = c.name if c else (scene or 'default')
    return report, session
