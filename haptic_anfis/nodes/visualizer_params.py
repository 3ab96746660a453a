"""The ``visualizer`` node's parameters: the contact detector's mesh parameters and the drawing's
(rate, probe, tumours, dent); units SI (metres, hertz) as the node reads them."""
from __future__ import annotations

from .contact_detector import MESH_PARAMS
from .parameters import Param, non_negative, positive

__all__ = ['PARAMS']


def _tumour_check(v):
    if len(v) % 4:
        return 'expected a flat list x, y, z, radius per tumour (a multiple of 4 numbers)'
    return None if all(r > 0 for r in v[3::4]) else 'tumour radii must be > 0'


PARAMS = MESH_PARAMS + [
    Param('rate', 30.0, 'marker rate [Hz]', positive),
    Param('force_scale', 0.01, 'force arrow length per newton [m/N]', positive),
    Param('probe_radius', 0.008, 'probe radius [m] (the flat FE probe, drawn as a cylinder)',
          positive),
    Param('show_tumours', False, 'draw the tumours'),
    Param('tumours', [0.0285, 0.015, -0.010, 0.0075], 'tumours, flat x, y, z, radius [m] per '
          'tumour (tissue frame; default: the default FE scene\'s tumour, '
          'config/scenes/default.yaml)', _tumour_check),
    Param('mesh_alpha', 0.5, 'tissue mesh opacity (0..1)',
          lambda v: None if 0 <= v <= 1 else 'expected 0 <= value <= 1'),
    Param('deform', True, 'draw the dent under the probe (FE skin displacements)'),
    Param('displacement_path', '', "skin displacement file of the force data "
          "('' = the shipped default scene's, haptic_anfis/data/default_forces.displacement.npz)"),
    Param('dent_reach', 5.0, 'the drawn dent fades to exactly 0 at this many probe radii from '
          'the probe axis (fade over the last probe radius; at most 9.0)',
          lambda v: None if 2.0 < v <= 9.0 else 'expected 2.0 < value <= 9.0'),
    Param('patch_size', 0.008, 'edge of the square (y, z) patches the surface is re-sent in [m]',
          positive),
    Param('dent_tolerance', 0.0001, 'a patch is re-sent when one of its corners would move by '
          'more than this [m]', non_negative),
    Param('max_points_per_message', 1500, 'triangle corners per dent message (bounds how long '
          'one publish holds the interpreter)', lambda v: None if v >= 3 else 'expected >= 3'),
]
