"""Examination mode (no ROS): coverage of the skin per pressure level, search pattern, marks against
lesions, score, verdict, report JSON + figure; the simulated trainees and their lump detector.

- :class:`ExamSession` (``session``): samples in, :meth:`~ExamSession.report` out.
- :class:`CoverageGrid` (``coverage``), :func:`classify` (``pattern``), :func:`match` (``findings``).
- :func:`subject_from_scene` (``lesions``): the lesions a case defines (swap in a case library here).
- :mod:`.trainee`: systematic / careless trainee scripts and the force-only lump detector.
"""
from .config import LEVELS, ExamConfig, load_exam_config
from .coverage import CoverageGrid
from .findings import match, project_marks
from .lesions import ExamSubject, Lesion, lesion_surface_points, subject_from_scene
from .pattern import classify
from .session import ExamSession, Surface, score_of, verdict_of

__all__ = ['LEVELS', 'CoverageGrid', 'ExamConfig', 'ExamSession', 'ExamSubject', 'Lesion',
           'Surface', 'classify', 'lesion_surface_points', 'load_exam_config', 'match',
           'project_marks', 'score_of', 'subject_from_scene', 'verdict_of']
