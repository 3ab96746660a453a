"""The haptic device side (no ROS): the compiled servo tick, device interface, simulated Falcon
with a scripted virtual hand, servo-loop timing statistics.

- :mod:`.native_tick` / :mod:`.servo_native`: the servo tick of every backend (device, clutch,
  local model, passivity, the safety rules of :mod:`.safety`), compiled, on its own workers or
  in a servo process; :mod:`.driver_loops`: the loop a driver runs, from a table.
- :class:`SimulatedFalcon`: 10 cm workspace, force clamped to ``max_force`` (default
  :data:`RATED_FORCE`, 8.9 N), handle pulled by a mass-spring-damper hand.
- :class:`PalpationScript`: the hand's scripted pattern (press, strips, circles) from YAML.
- :class:`WorkspaceMapping`: device frame <-> tissue frame (scale, offset, force scale).
- :class:`LoopStats`: rate, latency percentiles, deadline misses.
- :mod:`.loop_health`: whether the loop kept its period over the last window (the driver's
  live warning).

A real Novint Falcon (not imported here; its USB library is the optional ``falcon`` extra):
:mod:`.falcon_protocol` (packets), :mod:`.falcon_kinematics` (delta robot, SI units),
:mod:`.falcon_usb` (``FalconUSB``: the same device interface over USB, with a stall guard,
disconnect detection and reconnect), :mod:`.falcon_check` (the step-by-step hardware check and the
force-scale calibration behind ``haptic-anfis falcon check``).
"""
from .falcon import RATED_FORCE, Device, DeviceState, HandParams, SimulatedFalcon, WorkspaceMapping
from .palpation import PalpationScript, dome_height
from .safety import SafetyStats
from .stats import LoopStats

__all__ = ['RATED_FORCE', 'Device', 'DeviceState', 'HandParams', 'LoopStats', 'PalpationScript',
           'SafetyStats', 'SimulatedFalcon', 'WorkspaceMapping', 'dome_height']
