"""The topics' names and message layouts: :mod:`haptic_anfis.interfaces` (a core module, so the
bag layer reads them without importing the nodes); re-exported here for the nodes."""
from __future__ import annotations

from ..interfaces import *  # noqa: F401,F403
from ..interfaces import CONTACT_FIELDS, SERVICE_RELOAD  # noqa: F401  (explicit for readers)
