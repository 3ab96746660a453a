"""The haptic surface and the force data describe the same tissue (issue 3's 'by construction')."""
import warnings

import numpy as np

from haptic_anfis.contact import ContactDetector
from haptic_anfis.tissue.dataset import DEFAULT_DATASET, load_dataset
from haptic_anfis.pipeline.contact import DEFAULT_SURFACE, load_surface

PARAMS = {'mesh_path': '', 'mesh_unit': 'mm', 'dome_radii': [0.045, 0.07, 0.07]}


def test_default_surface_loads_clean_and_closed():
    with warnings.catch_warnings():
        warnings.simplefilter('error')  # no duplicate-vertex or open-mesh warnings
        mesh = load_surface(PARAMS)
        det = ContactDetector(mesh, direction=(-1.0, 0.0, 0.0))
    assert DEFAULT_SURFACE.is_file()
    assert mesh.is_watertight
    assert det.n_faces > 1000


def test_dataset_contact_points_lie_on_the_default_surface():
    ds = load_dataset(DEFAULT_DATASET)
    det = ContactDetector(load_surface(PARAMS), direction=(-1.0, 0.0, 0.0))
    points = np.unique(ds.X[:, :3], axis=0)
    d = det.query_many(points).signed_distance
    # Within the facetting error of ~2 mm triangles on a 45-70 mm ellipsoid (sagitta < 0.1 mm).
    assert np.max(np.abs(d)) < 1e-4, np.max(np.abs(d))
