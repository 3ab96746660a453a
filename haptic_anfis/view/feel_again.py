""""Feel it again": a lesion of a debrief pressed once more, by the simulated Falcon's scripted
hand (no ROS).

:func:`feel_script` is a palpation script (:mod:`haptic_anfis.device.palpation`) that presses
straight in over the lesion at the exam's light, medium and deep bands, then the same beside it
(as much tissue without the lesion, for the contrast), and loops. :func:`write_feel_again`
writes it and a parameter file giving it to the falcon driver, and returns the command that runs
it, on the lesion's case, with the trainee's page open:
``haptic-anfis sim --case NAME --view --duration 120 --params-file FILE``. With a real Falcon the
trainee presses there by hand: the page draws the probe over the skin, and the debrief says where.
"""
from __future__ import annotations

import os
import tempfile
from pathlib import Path

import yaml

from ..cases import CaseError, library
from ..tissue.scene import load_scene

__all__ = ['FEEL_DURATION', 'feel_commands', 'feel_script', 'write_feel_again']

#: [s] how long the command's session runs
FEEL_DURATION = 120.0
#: [s] each press held
HOLD = 1.5
#: the hand aims this much deeper than the band it is to reach: the tissue force pushes the
#: handle back (measured: aiming 12 mm reached 7.9 mm, short of the 8 mm band)
OVERSHOOT = 2.0


def feel_script(lesion_yz, lesion_radius: float, radii, thresholds) -> dict:
    """The script (a mapping, as the YAML) pressing over the lesion at (y, z) [m] at each of
    ``thresholds`` (light, medium, deep) [m] x :data:`OVERSHOOT`, then beside it, ``2.5 x
    lesion_radius + 8 mm`` towards the breast's middle, looped; ``radii`` the breast's
    semi-axes [m]."""
    y, z = (float(v) for v in lesion_yz)
    off = 2.5 * float(lesion_radius) + 0.008
    sign = -1.0 if y > 0 else 1.0   # beside it, towards the middle: still on the breast
    depths = [round(OVERSHOOT * float(t), 4) for t in thresholds]
    over = [{'press': {'points': [[y, z]], 'depth': d, 'hold': HOLD}} for d in depths]
    beside = [{'press': {'points': [[y + sign * off, z]], 'depth': d, 'hold': HOLD}}
              for d in depths]
    return {'surface': {'radii': [float(r) for r in radii]}, 'approach_height': 0.008,
            'travel_speed': 0.08, 'press_speed': 0.02, 'start_delay': 0.5, 'loop': True,
            'pattern': over + [{'pause': {'duration': 1.0}}] + beside
            + [{'pause': {'duration': 1.0}}]}


def write_feel_again(case: str, lesion: dict, thresholds, directory: str | os.PathLike
                     ) -> str:
    """Write the script pressing ``lesion`` (a report entry: ``name``, ``surface_mm``,
    ``radius_mm``) of library case ``case`` and its parameter file into ``directory``; return
    the command that feels it again.

    Raises:
        CaseError (a ValueError): ``case`` is not in the library.
    """
    scene = load_scene(library().get(case).scene_path)
    d = Path(directory)
    d.mkdir(parents=True, exist_ok=True)
    s = [c * 1e-3 for c in lesion['surface_mm']]
    script = d / f"feel_{lesion['name']}.yaml"
    script.write_text(yaml.safe_dump(feel_script((s[1], s[2]), lesion['radius_mm'] * 1e-3,
                                                 scene.radii, thresholds), sort_keys=False))
    params = d / f"feel_{lesion['name']}_params.yaml"
    params.write_text(yaml.safe_dump({'falcon_driver': {'ros__parameters': {
        'palpation_script': str(script.resolve())}}}))
    return (f'haptic-anfis sim --case {case} --view --duration {FEEL_DURATION:g} '
            f'--params-file {params.resolve()}')


def feel_commands(case: str, lesions: list[dict], thresholds,
                  directory: str | os.PathLike | None = None) -> dict[str, str]:
    """{lesion name: :func:`write_feel_again`'s command} for each palpable lesion of the report
    entries ``lesions`` of library case ``case``, the files in ``directory`` (None: a folder of
    the temporary directory); {} for a case not in the library or nowhere to write."""
    d = Path(directory) if directory is not None else \
        Path(tempfile.gettempdir()) / 'haptic_anfis_feel_again' / str(case)
    out = {}
    for e in lesions:
        if e.get('palpable') is False:
            continue
        try:
            out[e['name']] = write_feel_again(case, e, thresholds, d)
        except (CaseError, OSError):   # not a library case, or nowhere to write: no step
            return {}
    return out
