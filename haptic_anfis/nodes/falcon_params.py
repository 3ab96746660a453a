"""The ``falcon_driver`` node's parameters (:data:`PARAMS`: name, default, help, check) and
their resolution (:func:`resolve`); the node is :mod:`.falcon_driver`."""
from __future__ import annotations

import math

from ..device.falcon import RATED_FORCE
from ..device.force_input import MODES
from ..device.limits import check_max_force, check_rate, check_watchdog
from ..device.local_model import (APPROACH_RADIUS, FALCON_MAX_STIFFNESS, HOLD_RADIUS,
                                  MODEL_BLEND_TIME, PASSIVITY_WINDOW)
from .parameters import (Param, ParameterError, finite_vector, non_negative, one_of,
                         positive)

BACKENDS = ('sim', 'falcon')
#: the driver's servo loops (:data:`haptic_anfis.device.driver_loops.LOOPS`): all the compiled
#: tick, on threads of the driver ('native') or in a servo process of its own
SERVO_LOOPS = ('auto', 'native', 'native_process')

PARAMS = [
    Param('backend', 'sim', "device backend: 'sim' (simulated Falcon with a scripted virtual hand) "
          "or 'falcon' (a Novint Falcon over USB; needs pip install 'haptic_anfis[falcon]')",
          one_of(*BACKENDS)),
    Param('rate', 1000.0, 'servo loop rate [Hz], 100-1000 (what the Falcon runs; '
          'haptic_anfis.device.limits)', check_rate),
    Param('frame_id', 'tissue', 'frame of the published pose/velocity/force and of accepted '
          'force commands (others are rejected)'),
    Param('max_force', RATED_FORCE, 'device force limit [N]; commands are clamped to it (default: the '
          "Falcon's rated force, > 2 lbf = 8.9 N per Novint's specification, also its bound: "
          'haptic_anfis.device.limits)', check_max_force),
    Param('max_force_rate', 1000.0, 'largest change of the applied force [N/s]', positive),
    Param('watchdog_timeout', 0.010, 'no force command for this long [s] ramps the force to zero '
          '(at max_force_rate); 0.001-0.05 (haptic_anfis.device.limits)', check_watchdog),
    Param('workspace_scale', 1.5, 'tissue position = workspace_offset + workspace_scale * device '
          'position', positive),
    Param('workspace_offset', [0.03, 0.0, 0.0], 'tissue-frame position of the device origin [m]',
          finite_vector(3)),
    Param('force_scale', 1.0, 'device force = force_scale * commanded (tissue) force; sim, launch '
          "and exam run set it from their case (haptic_anfis.cases.force_mapping: the case's "
          'largest trained FE force at 85 % of max_force) unless it is given; writable: a case '
          "chosen on the browser page sets that case's while the loop runs", positive),
    Param('palpation_script', '', "sim: YAML palpation pattern ('' = config/palpation.yaml)"),
    Param('hold_until_force', True, 'sim: hold the virtual hand at the script start (and the force '
          'at zero) until the first valid force command arrives, i.e. until the contact detector '
          'and force server are up; false = the script runs from the start'),
    Param('hand_mass', 0.2, 'sim: hand + handle mass [kg]', positive),
    Param('hand_stiffness', 1000.0, 'sim: hand spring to the scripted target [N/m], device frame',
          positive),
    Param('hand_damping', 30.0, 'sim: hand damper [N s/m]', positive),
    Param('firmware_path', '', "falcon: Novint firmware file uploaded when the device runs none "
          "(after every power-up); '' = expect it running (none is shipped)"),
    Param('device_index', 0, 'falcon: which Falcon on the USB bus (0 = first)',
          lambda v: None if v >= 0 else 'expected an integer >= 0'),
    Param('device_serial', '', "falcon: USB serial number of the Falcon ('' = use device_index)"),
    Param('firmware_attempts', 3, 'falcon: firmware upload attempts before giving up (>= 1)',
          lambda v: None if v >= 1 else 'expected an integer >= 1'),
    Param('homing', True, 'falcon: home the arms at start (the user moves the grip out, then in; '
          'encoders are relative until homed)'),
    Param('homing_timeout', 30.0, 'falcon: seconds to wait for homing', positive),
    Param('gravity_compensation', False, 'falcon: add an upward force holding gravity_mass at '
          'the tip'),
    Param('gravity_mass', 0.1, 'falcon: grip + arm mass lumped at the tip [kg] (an estimate: tune '
          'per device)', non_negative),
    Param('stall_timeout', 0.05, 'falcon: no packet sent for this long [s] (servo loop stalled): '
          'a guard thread sends zero force to the device and logs it (default above the servo '
          "thread's measured worst gap, bench/bench_falcon_jitter.py)", positive),
    Param('disconnect_after', 200, 'falcon: this many consecutive servo ticks without a reply (or '
          'with a USB error) mark the device disconnected: zero force, zero velocity, logged',
          lambda v: None if v >= 1 else 'expected an integer >= 1'),
    Param('reconnect', True, 'falcon: after a disconnect, try to reopen the device every '
          'reconnect_period (firmware and homing redone as needed); false: stop the node (exit 1)'),
    Param('reconnect_period', 1.0, 'falcon: seconds between reconnect attempts', positive),
    Param('max_motor_command', 32767, 'falcon: largest motor command [counts, <= 32767]; the three '
          'motor values are scaled together under it (the force keeps its direction)',
          lambda v: None if 1 <= v <= 32767 else 'expected an integer in 1..32767'),
    Param('counts_per_nm', 10000.0, "falcon: motor command counts per N m of motor torque "
          "(libnifalcon's uncalibrated scale; 'haptic-anfis falcon check --calibrate' measures it)",
          positive),
    Param('measured_cf_every', 10, 'publish the applied force every N servo ticks (>= 1)',
          lambda v: None if v >= 1 else 'expected an integer >= 1'),
    Param('run_duration', 0.0, 'stop this long [s] after the first force command arrives, print '
          'the loop statistics as one JSON line on stdout and exit (0 = run until shut down)',
          non_negative),
    Param('force_mode', 'local_model', "'local_model': render the force server's local force model "
          "(F0 + K (p - p0)) at every servo tick; 'zoh': hold the newest force command "
          '(zero-order hold)', one_of(*MODES)),
    Param('model_validity_time', 0.05, 'local_model: a model older than this [s] (from its pose) '
          'expires: the last force is held and the watchdog ramps it to zero', positive),
    Param('model_validity_radius', 0.005, 'local_model: beyond this [m] (tissue frame) from the '
          'model\'s position the depth is still followed but the offset across the indentation '
          'direction is held at it (no 0 N mid-press; counted as ticks_beyond)', positive),
    Param('model_approach_radius', APPROACH_RADIUS, 'local_model: an approach model (the surface '
          'plane ahead of a free probe) renders zero with the probe further than this [m] '
          '(tissue frame) along the plane from its point: a convex surface lies under its tangent '
          'plane, r^2 / 2R off at r', positive),
    Param('max_stiffness', FALCON_MAX_STIFFNESS, 'local_model: stiffness bound [N/m] in the DEVICE '
          'frame (3000.0: the Falcon figure CHAI3D uses); the model is clamped to it', positive),
    Param('trace_path', '', "write every servo tick (time, position, applied force, model status) "
          "and the loop statistics to this .npz file at shutdown ('' = no trace)"),
    Param('trace_seconds', 600.0, 'trace_path: the trace keeps the last this many seconds of '
          'ticks (600 s at 1 kHz: ~39 MB); 0 = every tick of the run (~230 MB an hour)',
          non_negative),
    Param('take_in_servo_thread', True, 'take falcon/servo_cf and falcon/servo_cf_local from '
          'their readers in the servo thread at the start of each tick (true), instead of in '
          'executor callbacks (false): no GIL hand-over per message'),
    Param('gil_switch_interval', 0.0002, "this process's Python thread switch interval [s]: how "
          'long another thread may hold the GIL before the servo thread gets it back (Python '
          'default 0.005; 0 = leave it)', non_negative),
    Param('servo_loop', 'auto', "sim: 'native' runs the servo tick (device, local model, "
          'clutch, safety, passivity bound) compiled on threads of the driver without the '
          "interpreter lock (haptic_anfis.device.servo_native); 'native_process' the same "
          "compiled loop in a servo process of its own session on shared memory; 'auto': "
          "'native_process', which kept the period better "
          'than the threads under the normal scheduler and as well at real-time priority '
          "(docs/servo_loop.md). falcon: 'auto' and 'native_process' run the USB I/O "
          "and the compiled tick in the servo process (a frozen node cannot leave force on the "
          "motors); 'native' is refused (its USB library needs the interpreter)",
          lambda v: None if v in SERVO_LOOPS else
          f"expected one of {', '.join(map(repr, SERVO_LOOPS))} (each runs the compiled tick)"),
    Param('passivity_damping', 1.5, 'native: device damping b [N s/m] of the passivity bound on '
          'the rendered stiffness, K <= 2 b / T with T the measured tick periods of the last '
          'passivity_window, energy-weighted (sum T^2 / sum T; Colgate & Schenkel 1997; '
          'docs/servo_loop.md)', positive),
    Param('passivity_window', PASSIVITY_WINDOW, 'native: time constant [s] of the tick periods '
          'the passivity bound weighs (exponentially): one late tick lowers the rendered '
          'stiffness for about this long, a loop that keeps ticking late gets the bound of its '
          'period (docs/servo_loop.md)', positive),
    Param('model_hold_time', 1.0, 'native, local_model: a model older than model_validity_time '
          'but not than this [s] is still rendered (the tissue does not move, so an upstream stall '
          'does not drop the force to 0 N), and one arriving that old is still taken; then it '
          'expires and the watchdog ramps the force to zero (also how long a paused driver or a '
          'dead force server leaves the last model on the hand; docs/servo_loop.md). '
          '<= model_validity_time: off', positive),
    Param('model_hold_radius', HOLD_RADIUS, 'native, local_model: a held model (older than '
          'model_validity_time) is rendered only while the probe is within this [m] (tissue '
          'frame) of the model\'s position; further it is expired for those ticks and the '
          'watchdog ramps the force to zero (a held plane followed down the flank of a convex '
          'surface pressed on a free probe; docs/servo_loop.md). 1.0 (more than the '
          'workspace): off', positive),
    Param('model_blend_time', MODEL_BLEND_TIME, 'native, local_model: the step between two '
          'successive local models is ramped out over the old model\'s age, at most this [s], '
          'where both press on the probe (a model that comes late does not jolt the hand: a '
          'step of 0.2 N is a ripple window; a release is never faded; docs/servo_loop.md). '
          '0: off',
          non_negative),
    Param('passivity_observer', False, 'native: run the passivity observer / controller '
          '(Hannaford & Ryu 2002) on the rendered port'),
    Param('servo_workers', 2, "native, native_process with the simulated Falcon: threads "
          'that serve the one 1 kHz tick schedule, each pinned to its own core; the first to '
          'wake runs the tick, so one core held busy costs no tick, and a tick whose '
          'worker was preempted mid-tick is taken over a period later (measured: '
          'docs/servo_loop.md). At most the cores the process may use; 1: one servo thread. '
          "The real Falcon's servo process has one (its USB I/O)",
          lambda v: None if 1 <= v <= 8 else 'expected 1 to 8'),
    Param('servo_priority', 50, 'real-time priority of the servo thread (SCHED_FIFO 1-99; 0 = '
          'the normal scheduler). Needs CAP_SYS_NICE or an rtprio limit (ulimit -r); without it '
          'the thread keeps the normal scheduler and a warning says how to allow it',
          lambda v: None if 0 <= v <= 99 else 'expected 0 to 99'),
    Param('loop_check_period', 10.0, 'every this many seconds [s] the servo loop\'s counters '
          'are checked, and a warning says when it lost more than 0.5 % of its periods (below '
          '995 Hz at 1 kHz) or had a gap between ticks longer than watchdog_timeout in that '
          'window (a machine starving the loop: the force the hand feels is late or held; at '
          'most one warning a minute, with the count of windows behind); 0 = never',
          lambda v: None if v == 0 or (math.isfinite(v) and v >= 1) else
          'expected 0 (never) or a finite number >= 1 s'),
]


def resolve_servo_loop(choice: str, backend: str = 'sim') -> str:
    """``servo_loop: auto`` made concrete: the compiled loop in a servo process of its own
    session, for both backends. With two tick workers it kept the period and the force in
    ``sim`` and ``launch`` at real-time priority as well as the threads in the driver's process,
    and better than they did without it, beside busy processes with the recorder and the view
    (docs/servo_loop.md, the measured pages it names). The Falcon
    needs it besides: its USB library is Python, and on a thread it would share the node's
    interpreter lock. Other choices pass through.

    Raises:
        ParameterError: ``native`` (a thread) with the falcon backend.
    """
    if backend == 'falcon' and choice == 'native':
        raise ParameterError("falcon_driver: servo_loop: got 'native' with backend 'falcon'; "
                             "expected 'auto' or 'native_process' (the USB I/O and the "
                             "compiled tick in a servo process): the Falcon's USB library "
                             "needs the interpreter, which a compiled thread does not hold")
    return 'native_process' if choice == 'auto' else choice


def resolve(p: dict, node: str = 'falcon_driver') -> dict:
    """The declared parameters ``p`` made concrete in place (``servo_loop``,
    :func:`resolve_servo_loop`) and checked across each other (``max_force`` against the
    backend's bound, which the declaration could not know); returns ``p``.

    Raises:
        ParameterError: one line naming the parameter and what was expected.
    """
    p['servo_loop'] = resolve_servo_loop(p['servo_loop'], p['backend'])
    why = check_max_force(p['max_force'], p['backend'])
    if why:
        raise ParameterError(f"{node}: bad parameters: parameter 'max_force' = "
                             f"{p['max_force']!r}: {why}")
    return p
