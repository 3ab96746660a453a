"""Force datasets from recorded sessions: what the trainer learns from when there is no FE data.

A session bag holds the contact messages (contact point on the undeformed surface, depth) and the
force commands computed from them; the force server stamps each command with its contact's stamp,
so the two pair up exactly. Each in-contact pair is one sample. Samples are grouped into surface
patches (a square grid of ``cell`` metres in the chest plane y-z) so that a train/test split holds
out whole patches, as the FE data holds out whole loading points.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from ..tissue.dataset import DatasetError, ForceDataset, load_dataset
from .. import interfaces as ifc
from .errors import BagError
from .reader import check_bag_path, read_messages
from .topics import JOINT_STATE_TYPE, WRENCH_TYPE, absolute


def _ns(stamp) -> int:
    return int(stamp.sec) * 1_000_000_000 + int(stamp.nanosec)


def dataset_from_bag(path: str | Path, contact_topic: str = ifc.TOPIC_CONTACT,
                     wrench_topic: str = ifc.TOPIC_COMMAND, cell: float = 0.005) -> ForceDataset:
    """Samples (x, y, z, depth) -> (Fx, Fy, Fz) from a recorded session.

    Args:
        path: the bag (directory or .mcap).
        contact_topic, wrench_topic: the recorded contact and force-command topics.
        cell: patch size [m] of the point groups used by splits.
    Raises:
        BagError: not a bag, topics missing or of the wrong type, no in-contact samples.
    """
    ct, wt = absolute(contact_topic), absolute(wrench_topic)
    contacts: dict[int, tuple] = {}
    wrenches: dict[int, tuple] = {}
    layouts = ifc.ContactLayouts()   # either contact layout read; other lengths counted
    for topic, _, _, msg in read_messages(path, [ct, wt],
                                          expect_types={ct: JOINT_STATE_TYPE, wt: WRENCH_TYPE}):
        stamp = _ns(msg.header.stamp)
        if topic == ct:
            v = msg.position
            if (layouts.accept(v) and v[ifc.I_IN_CONTACT] > 0.5
                    and v[ifc.I_DEPTH] > 0.0):
                contacts[stamp] = (v[ifc.I_X], v[ifc.I_Y], v[ifc.I_Z], v[ifc.I_DEPTH])
        else:
            f = msg.wrench.force
            wrenches[stamp] = (f.x, f.y, f.z)
    stamps = sorted(set(contacts) & set(wrenches))
    if not stamps:
        raise BagError(f'{path}: no in-contact samples with a matching force command on '
                       f'{ct} and {wt}; expected a session recorded with contact and force topics'
                       + (f' ({layouts.note()})' if layouts.note() else ''))
    X = np.array([contacts[s] for s in stamps], dtype=np.float64)
    Y = np.array([wrenches[s] for s in stamps], dtype=np.float64)
    cells = np.floor(X[:, 1:3] / cell).astype(np.int64)
    _, point = np.unique(cells, axis=0, return_inverse=True)
    provenance = {'kind': 'recorded session (force commands of the model that ran it)',
                  'contact_messages': layouts.as_dict(),
                  'bag': str(path), 'contact_topic': ct, 'wrench_topic': wt,
                  'patch_cell_m': cell, 'n_samples': len(stamps)}
    return ForceDataset(X=X, Y=Y, point=point.ravel(), provenance=provenance)


def load_training_data(path: str | Path) -> ForceDataset:
    """A dataset CSV, or a recorded session bag (directory with metadata.yaml, or .mcap)."""
    p = Path(path)
    if p.is_dir() or p.suffix in ('.mcap', '.db3'):
        try:
            check_bag_path(p)
        except BagError as exc:
            raise DatasetError(str(exc)) from None
        return dataset_from_bag(p)
    return load_dataset(p)
