"""Examination mode (no ROS): coverage of the skin per pressure level, search pattern, marks against
lesions, score, verdict, report JSON + figure; the simulated trainees and their lump detector.

- :class:`~haptic_anfis.exam.session.ExamSession`: samples in,
  :meth:`~haptic_anfis.exam.session.ExamSession.report` out.
- :class:`~haptic_anfis.exam.coverage.CoverageGrid`, :func:`~haptic_anfis.exam.pattern.classify`,
  :func:`~haptic_anfis.exam.findings.match`.
- :func:`~haptic_anfis.exam.lesions.subject_from_scene`: the lesions a case defines.
- :mod:`~haptic_anfis.exam.trainee`: systematic / careless trainee scripts and the force-only lump
  detector.

The package imports none of its modules, so importing one (``exam.config`` for a command's
``--help``) does not load the contact detector and trimesh that ``exam.session`` needs.
"""

__all__: list[str] = []  # a package of modules, imported by name (haptic_anfis.exam.<module>)
