"""Tissue scenes and finite-element force data (no ROS imports).

- :mod:`.scene`: YAML scene files (mm/kPa at the edge, SI inside), validated.
- :mod:`.geometry`: loading points, normals, the tissue surface mesh (trimesh).
- :mod:`.mesh`: per-point structured hexahedral meshes with the probe outline as a mesh line.
- :mod:`.fe`: felupe load path of one loading point (needs the ``fe`` extra).
- :mod:`.sweep`: parallel, resumable sweep into a :class:`~haptic_anfis.tissue.dataset.ForceDataset`.
- :mod:`.validation`: Sneddon and Hayes et al. flat-punch references; :mod:`.report`: plots.
"""

__all__: list[str] = []  # a package of modules, imported by name (haptic_anfis.tissue.<module>)
