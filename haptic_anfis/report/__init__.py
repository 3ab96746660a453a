"""The speed-against-error report (``haptic-anfis report``): our ANFIS models and peers from
well-kept libraries, trained and measured on the same split in one run; Markdown + PNG figures
(:mod:`~haptic_anfis.report.run`; the models compared: :mod:`~haptic_anfis.report.peers`).
Needs the ``report`` extra (matplotlib, scikit-learn); the xanfis peer runs in its own virtualenv.
The package imports none of its modules: :mod:`~haptic_anfis.report.cv` (grouped
cross-validation, used by the case build) loads neither of those.
"""

__all__: list[str] = []  # a package of modules, imported by name (haptic_anfis.report.<module>)
