"""Compile (or load from numba's cache) the kernels the nodes use, before a session needs them:
``haptic-anfis warmup``, run by ``make venv``. Where the cache is: :mod:`haptic_anfis.numba_cache`.
"""
from __future__ import annotations

import time

from .anfis import ForceModel
from .contact import ContactDetector, ContactTracker, load_mesh
from .device.palpation import PalpationScript
from .device.servo_native import NativeServoLoop
from .resources import config_file
from .tissue.dataset import DATA_DIR

__all__ = ['PARTS', 'warm']


def _warm_force_model() -> None:
    ForceModel.load(DATA_DIR / 'default_model.json')  # compiles and warms the real-time path


def _warm_contact() -> None:
    mesh = load_mesh(DATA_DIR / 'default_surface.stl', unit='mm')  # the node's default surface
    mesh.merge_vertices()
    tracker = ContactTracker(ContactDetector(mesh, direction=(-1.0, 0.0, 0.0)))
    tracker.update((0.06, 0.0, 0.0))
    tracker.update((0.04, 0.0, 0.0))


def _warm_servo_tick() -> None:
    # the compiled loop the simulated Falcon runs, then the tick a real Falcon's servo process
    # calls around each USB exchange (compiled there before the device opens)
    NativeServoLoop(PalpationScript.from_yaml(config_file('palpation.yaml'))).compile()
    NativeServoLoop(None, device_factory=_no_device).compile()


def _no_device() -> None:
    """A device factory never called: :meth:`NativeServoLoop.compile` only needs to know the
    loop will drive a real device."""
    raise RuntimeError('the warm-up opens no device')


#: what :func:`warm` compiles, by name
PARTS = {'force_model': _warm_force_model, 'contact': _warm_contact,
         'servo_tick': _warm_servo_tick}


def warm(parts: tuple[str, ...] = tuple(PARTS)) -> dict[str, float]:
    """Compile (or load from the cache) the kernels the nodes use: the force model's, the
    contact detector's and the servo tick's (``parts``: names of :data:`PARTS`). Returns
    seconds per part."""
    unknown = [p for p in parts if p not in PARTS]
    if unknown:
        raise ValueError(f'warm: unknown part(s) {unknown}; expected some of {list(PARTS)}')
    out = {}
    for name in parts:
        t = time.perf_counter()
        PARTS[name]()
        out[name] = time.perf_counter() - t
    return out
