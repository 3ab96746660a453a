"""Stage 1 of the per-message pipeline (:mod:`haptic_anfis.pipeline`): probe pose -> contact
message values, on the tissue surface (metres, tissue frame)."""
from __future__ import annotations

from .. import interfaces as ifc
from ..contact import ContactDetector, ContactTracker, ellipsoid_dome, load_mesh
from ..contact.approach import surface_ahead
from ..contact.proxy import FREE
from ..tissue.dataset import DATA_DIR

__all__ = ['DEFAULT_SURFACE', 'approach_values', 'contact_values', 'load_surface',
           'make_tracker']

#: Surface mesh of the default FE scene (config/scenes/default.yaml), in millimetres.
DEFAULT_SURFACE = DATA_DIR / 'default_surface.stl'

_N_CONTACT = len(ifc.CONTACT_FIELDS)


def load_surface(p: dict):
    """The tissue mesh (a ``trimesh.Trimesh``, metres, tissue frame) named by the mesh parameter
    values ``p`` (``mesh_path``: a file, '' = :data:`DEFAULT_SURFACE`, 'dome' = a semi-ellipsoid
    with ``dome_radii`` [m]; ``mesh_unit``: 'mm' or 'm' of the file)."""
    if p['mesh_path'] == 'dome':
        return ellipsoid_dome(tuple(p['dome_radii']))
    path, unit = (p['mesh_path'], p['mesh_unit']) if p['mesh_path'] else (DEFAULT_SURFACE, 'mm')
    mesh = load_mesh(path, unit=unit)
    # Files such as STL store every triangle's corners separately: join equal vertices so the
    # surface is connected (same faces and coordinates, so the same contact answers).
    mesh.merge_vertices()
    return mesh


def make_tracker(p: dict) -> ContactTracker:
    """The contact tracker from the contact detector's parameter values ``p`` (mesh parameters,
    ``direction`` (3,) (all zeros = along the surface normal), ``max_step`` [m], ``max_depth`` [m],
    0 = no cap): the node and the re-simulation build it here, so a replay is configured exactly
    like the node."""
    mesh = load_surface(p)
    d = p['direction']
    detector = ContactDetector(mesh, direction=None if not any(d) else d)
    return ContactTracker(detector, max_step=p['max_step'], max_depth=p['max_depth'] or None)


def contact_values(tracker: ContactTracker, frame_id: str, pose_frame: str, xyz):
    """One pose through the tracker: ``(position values of the contact message (12,), TrackedContact
    or None, error or None)``. ``xyz`` (3,) [m] in ``pose_frame``, which must be the tissue frame
    ``frame_id``. A pose in another frame or with NaN/Inf gives "no contact" (zeros) and resets
    the tracker, so the next good pose cannot start a contact from inside."""
    if pose_frame != frame_id:
        tracker.reset()
        return [0.0] * _N_CONTACT, None, f'pose in frame {pose_frame!r}, expected {frame_id!r}'
    try:
        c = tracker.update(xyz)
    except ValueError as exc:  # NaN/Inf pose: tracker reset, no contact
        tracker.reset()
        return [0.0] * _N_CONTACT, None, str(exc)
    cp, dv, nv = c.contact_point, c.direction, c.normal
    return [float(cp[0]), float(cp[1]), float(cp[2]), float(c.depth),
            float(dv[0]), float(dv[1]), float(dv[2]),
            1.0 if c.in_contact else 0.0, 1.0 if c.saturated else 0.0,
            float(nv[0]), float(nv[1]), float(nv[2])], c, None


def approach_values(tracker: ContactTracker, c, p, max_distance: float) -> list[float]:
    """The approach fields (:data:`~haptic_anfis.interfaces.APPROACH_FIELDS`: surface point ahead
    [m], outward normal there) for the tracker's answer ``c`` at the probe position ``p`` (3,) [m]:
    only while free (not in contact, not rejected) and a front surface lies within
    ``max_distance`` [m] along the indentation direction; else [] (:func:`~haptic_anfis.contact.
    approach.surface_ahead`)."""
    if c is None or c.state != FREE or max_distance <= 0.0:
        return []
    a = surface_ahead(tracker.detector, p, tracker.detector.direction, max_distance)
    if a is None:
        return []
    s, n, _ = a
    return [float(s[0]), float(s[1]), float(s[2]), float(n[0]), float(n[1]), float(n[2])]
