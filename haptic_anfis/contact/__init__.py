"""Contact detection between the haptic probe and the tissue surface (pure Python + numba, no ROS).

- :class:`ContactDetector`: stateless, exact queries (closest point, signed distance, depth).
- :class:`ContactTracker`: the stateful proxy (god-object) the 1 kHz loop uses.
- :func:`load_mesh`: read a mesh file into the tissue frame, in metres, with checks.
- :func:`ellipsoid_dome`: the semi-ellipsoid breast surface used by tests, benches and demos.
"""
from .detector import ContactBatch, ContactDetector, ContactResult
from .mesh_io import MeshWarning, load_mesh, validate
from .proxy import ContactTracker, TrackedContact
from .shapes import ellipsoid_dome

__all__ = ['ContactBatch', 'ContactDetector', 'ContactResult', 'ContactTracker', 'MeshWarning',
           'TrackedContact', 'ellipsoid_dome', 'load_mesh', 'validate']
