"""The speed-against-error report (``haptic-anfis report``): our ANFIS models and peers from
well-kept libraries, trained and measured on the same split in one run; Markdown + PNG figures.

Needs the ``report`` extra (matplotlib, scikit-learn); the xanfis peer runs in its own virtualenv.
"""
from .peers import Peer, default_peers
from .run import build_report, headline_table

__all__ = ['Peer', 'build_report', 'default_peers', 'headline_table']
