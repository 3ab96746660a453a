"""``falcon_driver``: owns the haptic device; a 1 kHz servo loop on its own thread.

Publishes the tip pose (``falcon/measured_cp``), velocity (``falcon/measured_cv``), the force it
applies (``falcon/measured_cf``, every ``measured_cf_every`` ticks) and the buttons
(``falcon/buttons``, on change and every 100 ticks), all in the tissue frame; button 0 is the
clutch and button 1 the mark (:class:`haptic_anfis.device.buttons.ClutchMark`; a mark is published
as ``exam/marks``, ``geometry_msgs/PointStamped`` at the probe tip); subscribes to the
force command ``falcon/servo_cf`` (``geometry_msgs/WrenchStamped``, tissue frame) and the local
force model ``falcon/servo_cf_local`` (``sensor_msgs/JointState``, layout in
:mod:`haptic_anfis.nodes.interfaces`). ``force_mode``: ``local_model`` (default) evaluates the
newest local model at every servo tick's position; ``zoh`` holds the newest command (the
zero-order hold). Either goes through the safety layer (:class:`haptic_anfis.device.SafetyLayer`:
clamp, rate limit, watchdog, NaN/wrong-frame rejection). A command or model is judged by the age
of the driver's own pose it answers (its stamp), not by its arrival; stale, future and unknown
stamps are refused and counted (:class:`haptic_anfis.device.force_input.ForceInput`). The servo
thread is not a ROS timer: it keeps its period whatever the executor is doing, and (by default,
``take_in_servo_thread``) it takes the force command and the local model itself from their
keep-last-1 readers at the start of each tick, as raw CDR (:mod:`.polled`, :mod:`.cdr`): no
rclpy message objects and no GIL hand-over per message. Pose -> command
latency (pose stamp to command arrival) and deadline misses are collected in
:attr:`FalconDriver.servo` ``.stats``; ``trace_path`` writes every servo tick for the applied-force
error (:mod:`haptic_anfis.device.force_error`).

With the simulated Falcon the tick itself is compiled and never takes the interpreter lock
(``servo_loop: native``, :mod:`haptic_anfis.device.servo_native`; ``native_process``: in a servo
process of its own): device, local model, clutch, safety and the passivity bound run there, and
the Python side above (publishing, taking commands and models) is a bridge thread that may fall
behind without costing a tick (docs/servo_loop.md). The real Falcon's USB I/O runs with that
compiled tick in the servo process (:mod:`haptic_anfis.device.device_process`): a frozen node
cannot leave force on the motors.
"""
from __future__ import annotations

import json
import math
import os
import sys
import time
from typing import Callable

import numpy as np
from geometry_msgs.msg import PointStamped, PoseStamped, TwistStamped, WrenchStamped
from sensor_msgs.msg import JointState, Joy

from ..device import (HandParams, PalpationScript, SafetyLayer, ServoLoop, SimulatedFalcon,
                      WorkspaceMapping)
from ..device.buttons import ClutchMark
from ..device.falcon import RATED_FORCE
from ..device.force_input import MODES, ForceInput
from ..device.local_model import APPROACH_RADIUS, FALCON_MAX_STIFFNESS, HOLD_RADIUS, \
    MODEL_BLEND_TIME, PASSIVITY_WINDOW, STATUS_NAMES
from ..device.loop_health import LoopHealth
from ..device.safety import OK
from ..device.start_gate import HeldScript
from ..device.stamps import STALE
from ..device.trace import TickTrace, save_trace
from . import cdr
from . import interfaces as ifc
from .base import HapticNode
from .polled import PolledSubscription
from ._common import (LOOP_QOS, Param, ParameterError, config_file, declare_parameters,
                      finite_vector,
                      non_negative, one_of, positive, run_node, set_stamp)

BACKENDS = ('sim', 'falcon')

PARAMS = [
    Param('backend', 'sim', "device backend: 'sim' (simulated Falcon with a scripted virtual hand) "
          "or 'falcon' (a Novint Falcon over USB; needs pip install 'haptic_anfis[falcon]')",
          one_of(*BACKENDS)),
    Param('rate', 1000.0, 'servo loop rate [Hz]', positive),
    Param('frame_id', 'tissue', 'frame of the published pose/velocity/force and of accepted '
          'force commands (others are rejected)'),
    Param('max_force', RATED_FORCE, 'device force limit [N]; commands are clamped to it (default: the '
          "Falcon's rated force, > 2 lbf = 8.9 N per Novint's specification)", positive),
    Param('max_force_rate', 1000.0, 'largest change of the applied force [N/s]', positive),
    Param('watchdog_timeout', 0.010, 'no force command for this long [s] ramps the force to zero '
          '(at max_force_rate)', positive),
    Param('workspace_scale', 1.5, 'tissue position = workspace_offset + workspace_scale * device '
          'position', positive),
    Param('workspace_offset', [0.03, 0.0, 0.0], 'tissue-frame position of the device origin [m]',
          finite_vector(3)),
    Param('force_scale', 1.0, 'device force = force_scale * commanded (tissue) force', positive),
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
          'compiled loop in a servo process of its own session on shared memory; '
          "'python' the Python tick; 'auto': 'native_process', which kept the period better "
          'than the threads under the normal scheduler and as well at real-time priority '
          "(docs/servo_loop.md). falcon: 'auto' and 'native_process' run the USB I/O "
          "and the compiled tick in the servo process (a frozen node cannot leave force on the "
          "motors); 'python' the Python tick on a thread of the node; 'native' is refused (its "
          "USB library needs the interpreter)",
          one_of('auto', 'native', 'native_process', 'python')),
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


#: the shortest time [s] between two warnings that the servo loop fell behind
WARN_EVERY = 60.0


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
                             "compiled tick in a servo process) or 'python': the Falcon's "
                             "USB library needs the interpreter, which a compiled thread "
                             "does not hold")
    return 'native_process' if choice == 'auto' else choice


class FalconDriver(HapticNode):
    def __init__(self, name: str = 'falcon_driver', **kw):
        super().__init__(name, **kw)
        p = self.params = declare_parameters(self, PARAMS)
        p['servo_loop'] = self.servo_loop = resolve_servo_loop(p['servo_loop'], p['backend'])
        if p['gil_switch_interval'] > 0:
            # A busy thread (bag writer, executor callbacks) keeps the GIL up to this long while
            # the 1 kHz servo thread waits: with a recorder in the same process the worst
            # pose->wrench latency was 4.0-4.7 ms at Python's 5 ms, 1.6-1.9 ms at 0.2 ms.
            sys.setswitchinterval(p['gil_switch_interval'])
        self.frame_id = p['frame_id']
        self.mapping = WorkspaceMapping(p['workspace_scale'], tuple(p['workspace_offset']),
                                        p['force_scale'])
        if p['backend'] == 'falcon':
            self.device = self._make_falcon(p) if p['servo_loop'] == 'python' else None
            what = (f"Falcon {p['device_serial'] or 'index ' + str(p['device_index'])}, homing "
                    f"{'on' if p['homing'] else 'off'}, gravity compensation "
                    f"{p['gravity_mass'] if p['gravity_compensation'] else 'off'}")
        else:
            script_path = p['palpation_script'] or str(config_file('palpation.yaml'))
            script = PalpationScript.from_yaml(script_path)  # ValueError naming the file -> exit 1
            script = HeldScript(script, held=p['hold_until_force'])
            self.device = SimulatedFalcon(script, self.mapping,
                                          HandParams(p['hand_mass'], p['hand_stiffness'],
                                                     p['hand_damping']),
                                          max_force=p['max_force'])
            what = f'script {script_path} ({script.duration:.1f} s)'
        self.native = None
        if p['backend'] == 'falcon' and p['servo_loop'] != 'python':
            self.native = self._make_native(p, None, self._falcon_factory(p))
            self.device, self.safety = self.native.device, self.native.safety
            self.native.on_disconnect, self.native.on_reconnect = (self._device_lost,
                                                                   self._device_back)
            self.clutch = self.native.clutch
        elif p['backend'] == 'sim' and p['servo_loop'] != 'python':
            self.native = self._make_native(p, script)
            self.device, self.safety = self.native, self.native.safety
            self.clutch = self.native.clutch  # the clutch / mark rules run in the compiled tick
        else:
            self.safety = SafetyLayer(p['max_force'], p['max_force_rate'],
                                      p['watchdog_timeout'], frame_id=self.frame_id)
            # Button 0 clutch (zero force, mapping follows the hand), button 1 mark (exam/marks).
            self.clutch = ClutchMark()
        self.input = ForceInput(self.safety, self.mapping, p['force_mode'], p['max_stiffness'],
                                p['model_validity_time'], p['model_validity_radius'],
                                1.0 / p['rate'],
                                clutch=None if self.native is not None else self.clutch,
                                approach_radius=p['model_approach_radius'])
        if self.native is not None:
            self.input.renderer = self.native.renderer
        self.pub_pose = self.create_publisher(PoseStamped, ifc.TOPIC_POSE, LOOP_QOS)
        self.pub_twist = self.create_publisher(TwistStamped, ifc.TOPIC_TWIST, LOOP_QOS)
        self.pub_applied = self.create_publisher(WrenchStamped, ifc.TOPIC_APPLIED, LOOP_QOS)
        self.pub_buttons = self.create_publisher(Joy, ifc.TOPIC_BUTTONS, 10)
        self.pub_mark = self.create_publisher(PointStamped, ifc.TOPIC_MARKS, 10)
        # the force server's local model layout: read at a known offset (cdr.JointStateWriter)
        self._lm_layout = cdr.JointStateWriter(self.frame_id, ifc.LOCAL_MODEL_FIELDS,
                                               len(ifc.LOCAL_MODEL_FIELDS))
        self._polled: list[tuple[PolledSubscription, object]] = []
        loop_inputs = [(WrenchStamped, ifc.TOPIC_COMMAND, self._on_command)]
        if p['force_mode'] == 'local_model':
            loop_inputs.append((JointState, ifc.TOPIC_LOCAL_MODEL, self._on_local_model))
        for msg_type, topic, handler in loop_inputs:
            if p['take_in_servo_thread']:  # read by the servo thread each tick (nodes/polled.py)
                self._polled.append((PolledSubscription(self, msg_type, topic, LOOP_QOS),
                                     handler))
            else:
                self.create_subscription(msg_type, topic, handler, LOOP_QOS, raw=True)
        self._pose, self._twist, self._applied = PoseStamped(), TwistStamped(), WrenchStamped()
        for m in (self._pose, self._twist, self._applied):
            m.header.frame_id = self.frame_id
        self._pose.pose.orientation.w = 1.0
        self._buttons = None
        self._cf_every = p['measured_cf_every']
        self._tick = 0
        self.run_duration = p['run_duration']
        self.first_command: float | None = None
        #: sim: a further condition for releasing the held hand (e.g. ``haptic-anfis sim``: the
        #: recorder in its own process has matched every loop topic); set it before the executor
        #: first spins. None = the first force command alone releases it.
        self.release_gate: Callable[[], bool] | None = None
        self.finished = False
        self.exit_code = 0
        self.trace_path = p['trace_path']
        if self.native is not None:
            self.servo = self.native
            self.native.on_state = self._publish_state
            self.native.trace = self._tick_trace(p)
        else:
            self.servo = ServoLoop(self.device, self.safety, p['rate'],
                                   on_state=self._publish_state, render=self.input.render,
                                   trace=self._tick_trace(p),
                                   priority=p['servo_priority'])
        self.get_logger().info(
            f"backend {p['backend']}, {p['rate']:.0f} Hz servo thread, max force "
            f"{p['max_force']} N, watchdog {p['watchdog_timeout'] * 1e3:.1f} ms, force "
            f"{p['force_mode']}, {what}")
        self.started = False
        self.health = LoopHealth(p['watchdog_timeout'])
        self.device_lost = False
        if p['loop_check_period'] > 0:
            from diagnostic_msgs.msg import DiagnosticArray
            self.pub_diag = self.create_publisher(DiagnosticArray, ifc.TOPIC_DIAGNOSTICS, 10)
            self.create_timer(p['loop_check_period'], self._check_loop)

    def _check_loop(self) -> None:
        """Warn when the servo loop fell behind since the last check
        (:class:`~haptic_anfis.device.loop_health.LoopHealth`), saying the likely cause and what
        to do; nothing while the device is lost (its loop skips ticks on purpose then)."""
        if not self.started:
            return
        windows = self.health.windows
        short = self.health.check(self.servo.stats.summary())
        if self.health.windows > windows and not self.device_lost:
            self._publish_health(short)
        if short is None or self.device_lost:
            return
        # a starved machine falls behind most windows: once a minute says it, with the count
        self.get_logger().warning(f'{short}; {self.behind_because()} ({self.health.behind} of '
                                  f'{self.health.windows} windows so far)',
                                  throttle_duration_sec=WARN_EVERY)

    def _publish_health(self, short: str | None) -> None:
        """The window just checked on ROS's diagnostics topic: WARN with ``short`` when it fell
        behind, else OK; the counts and the likely cause as values (the page shows them)."""
        from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
        st = DiagnosticStatus(name=ifc.LOOP_DIAGNOSTIC, hardware_id=self.params['backend'])
        st.level = DiagnosticStatus.WARN if short else DiagnosticStatus.OK
        st.message = short or 'kept its period'
        h = self.health
        st.values = [KeyValue(key=k, value=str(v)) for k, v in (
            ('windows', h.windows), ('windows_behind', h.behind),
            ('cause', self.behind_because()), ('scheduling', self.servo.scheduling))]
        msg = DiagnosticArray(status=[st])
        msg.header.stamp = self.get_clock().now().to_msg()
        self.pub_diag.publish(msg)

    def behind_because(self) -> str:
        """The likely cause of a servo loop falling behind, and what to do, from how it runs."""
        if self.servo_loop == 'python':
            return ('the servo tick runs in Python (servo_loop: python) and waits for the '
                    'interpreter lock; servo_loop: auto runs it compiled, in a process of its own')
        # the servo threads' policy as the kernel has it now (rtkit may have demoted them since
        # the start's scheduling line)
        from .processes import servo_realtime
        realtime = servo_realtime(os.getpid())
        if realtime:
            return ('the servo is real-time: the machine itself stalled'
                    + (", or the device's USB replies came late" if self.params['backend']
                       == 'falcon' else '') + ' (docs/servo_loop.md, "Stalls of the machine '
                    'itself")')
        if realtime is False:
            return ('the servo runs under the normal scheduler; real-time priority keeps the '
                    'period (docs/nodes.md, "The servo thread\'s priority")')
        return f'the servo thread\'s scheduling: {self.servo.scheduling or "not reported"}'

    def start_loop(self) -> None:
        """Start the servo loop (a real device is opened here: a FalconError / OSError). Called
        once the process has settled (:func:`~.runtime.run_node`, the one-process graph): the
        loop's bridge thread publishes the poses and takes the commands, and it shares this
        process's interpreter lock; started in ``__init__`` it waited behind the rest of the
        process's start (a first log call inspecting every module, the full garbage collection of
        ``settle_gc``): 40-340 ms after the first command had released the hand (launch, about
        one start in four). Idempotent."""
        if self.started:
            return
        self.servo.start()
        self.started = True
        self.health.check(self.servo.stats.summary())  # the first window starts here
        if 'refused' in self.servo.scheduling:  # one call site per severity (rclpy)
            self.get_logger().warning(f'servo thread: {self.servo.scheduling}')
        else:
            self.get_logger().info(f'servo thread: {self.servo.scheduling}')

    def _make_falcon(self, p):
        """The USB backend on a thread of this node (``servo_loop: python``). Connecting,
        firmware upload and homing happen when the servo loop opens it; a FalconError (an
        OSError) stops the node at start with its message."""
        return self._falcon_factory(p)(log=self.get_logger().info,
                                       on_disconnect=self._device_lost,
                                       on_reconnect=self._device_back)

    @staticmethod
    def _falcon_factory(p):
        """A callable building the USB backend from the parameters; it holds no ROS object, so
        the servo process can call it (its log and hooks are that process's own). The USB
        library is imported here, before any servo process is forked: a missing library is
        this node's one-line error (FalconUnavailableError) at start."""
        import dataclasses
        import functools

        from ..device.falcon_kinematics import GEOMETRY
        from ..device.falcon_usb import FalconUSB, import_ftdi
        import_ftdi()
        return functools.partial(
            FalconUSB, firmware_path=p['firmware_path'], device_index=p['device_index'],
            serial=p['device_serial'], firmware_attempts=p['firmware_attempts'],
            homing=p['homing'], homing_timeout=p['homing_timeout'],
            gravity_compensation=p['gravity_compensation'], gravity_mass=p['gravity_mass'],
            max_force=p['max_force'], stall_timeout=p['stall_timeout'],
            disconnect_after=p['disconnect_after'], reconnect=p['reconnect'],
            reconnect_period=p['reconnect_period'], max_motor_command=p['max_motor_command'],
            geometry=dataclasses.replace(GEOMETRY, counts_per_nm=p['counts_per_nm']))

    def _make_native(self, p, script, device_factory=None):
        """The compiled, GIL-free servo loop (device/servo_native.py): with the simulated Falcon,
        or with the real one opened in the servo process (``device_factory``)."""
        from ..device.servo_native import NativeServoLoop
        kw = {}
        if device_factory is not None:
            from ..device.falcon_usb import FalconError
            kw = dict(device_factory=device_factory, open_error=FalconError,
                      open_timeout=p['homing_timeout'] + 60.0)  # firmware upload + homing
        return NativeServoLoop(
            script, self.mapping, HandParams(p['hand_mass'], p['hand_stiffness'],
                                             p['hand_damping']),
            p['rate'], p['max_force'], p['max_force_rate'], p['watchdog_timeout'],
            self.frame_id, p['force_mode'], p['max_stiffness'], p['model_validity_time'],
            p['model_validity_radius'], p['passivity_damping'], p['passivity_observer'],
            p['model_hold_time'], trace=self._tick_trace(p),
            priority=p['servo_priority'], process=p['servo_loop'] == 'native_process',
            workers=p['servo_workers'], approach_radius=p['model_approach_radius'],
            hold_radius=p['model_hold_radius'], blend_time=p['model_blend_time'],
            passivity_window=p['passivity_window'], **kw)

    @staticmethod
    def _tick_trace(p) -> TickTrace | None:
        """The servo tick trace ``trace_path`` asks for: the last ``trace_seconds`` of ticks."""
        if not p['trace_path']:
            return None
        return TickTrace(max_rows=int(round(p['rate'] * p['trace_seconds'])))

    def _device_lost(self, why: str) -> None:
        """The Falcon backend lost the device (servo thread): zero the force; without reconnect,
        stop the node with exit status 1."""
        self.device_lost = True
        self.safety.stop()
        self.get_logger().error(why)
        if not self.params['reconnect']:
            self.exit_code = 1
            self.finished = True

    def _device_back(self, msg: str) -> None:
        self.device_lost = False
        self.get_logger().info(msg)
        self.safety.start(time.monotonic())  # force ramps up from zero

    # -- servo thread ---------------------------------------------------------------------------
    def _publish_state(self, state, force, now) -> None:
        for sub, handler in self._polled:  # the newest force command / local model first
            raw = sub.take()
            if raw is not None:
                handler(raw)
        ns = getattr(state, 'stamp_ns', 0) or time.time_ns()  # native: the tick's own stamp
        m = self.mapping
        (x, y, z), ev = self.clutch.update(state.buttons, m.to_tissue(state.position), now)
        pose = self._pose
        set_stamp(pose.header.stamp, ns)
        self.input.on_pose(ns, now)
        pos = pose.pose.position
        pos.x, pos.y, pos.z = x, y, z
        self.pub_pose.publish(pose)
        tw = self._twist
        tw.header.stamp = pose.header.stamp
        vx, vy, vz = (0.0, 0.0, 0.0) if self.clutch.held else m.velocity_to_tissue(state.velocity)
        lin = tw.twist.linear
        lin.x, lin.y, lin.z = vx, vy, vz
        self.pub_twist.publish(tw)
        self._tick += 1
        if self._tick % self._cf_every == 0:
            ap = self._applied
            ap.header.stamp = pose.header.stamp
            k = 1.0 / m.force_scale
            f = ap.wrench.force
            f.x, f.y, f.z = force[0] * k, force[1] * k, force[2] * k
            self.pub_applied.publish(ap)
        if state.buttons != self._buttons or self._tick % 100 == 0:
            self._buttons = state.buttons
            joy = Joy()
            joy.header.stamp = pose.header.stamp
            joy.header.frame_id = self.frame_id
            joy.buttons = list(state.buttons)
            self.pub_buttons.publish(joy)
        if ev.mark:  # the probe tip; the examiner projects it on the surface
            mk = PointStamped()
            mk.header.stamp, mk.header.frame_id = pose.header.stamp, self.frame_id
            mk.point.x, mk.point.y, mk.point.z = x, y, z
            self.pub_mark.publish(mk)
        if self.first_command is not None and self.run_duration > 0 \
                and now - self.first_command >= self.run_duration:
            self.finished = True

    # -- executor thread ------------------------------------------------------------------------
    # Both loop inputs arrive as raw bytes (nodes/cdr.py): rclpy's own deserialisation of a
    # message cost 25-100 µs of this process's GIL, which the servo thread needs every 1 ms.
    # They run on the servo thread (take_in_servo_thread, the default) or the executor's.
    def _on_command(self, raw: bytes) -> None:
        now = time.monotonic()
        try:
            stamp, frame, f = cdr.read_wrench_stamped(raw)
        except ValueError as exc:  # malformed: zero force, as for a non-finite command
            self._malformed(f'force command {exc}')
            return
        why = self.input.command(f, stamp, frame, now)
        if self.input.mode == 'zoh':
            self._arrived(why, stamp)
        if why != OK and not (why.endswith(STALE) and self.first_command is None):
            # (stale answers queued while the graph started are counted, not warned of)
            self.get_logger().warning(f'force command {why}: {f} in frame {frame!r}; '
                                      + ('not taken' if 'stamp' in why else 'applying zero force'),
                                      throttle_duration_sec=1.0)

    def _on_local_model(self, raw: bytes) -> None:
        now = time.monotonic()
        try:
            stamp, frame, v, _ = self._lm_layout.read(raw)
        except ValueError as exc:
            self._malformed(f'local force model {exc}')
            return
        # flat values: no LocalModel object on this path (GIL time per message)
        if len(v) == len(ifc.LOCAL_MODEL_FIELDS):
            why = self.input.model_values(v, stamp, frame, now)
        else:  # wrong length: zero force, as for a non-finite model
            why = (f'rejected: local force model message with {len(v)} values, expected '
                   f'{len(ifc.LOCAL_MODEL_FIELDS)}')
            self.input.renderer.clear()
            self.safety.reject(why)
        self._arrived(why, stamp)
        if why != OK and not (why.endswith(STALE) and self.first_command is None):
            self.get_logger().warning(f'local force model {why}', throttle_duration_sec=1.0)

    def _malformed(self, why: str) -> None:
        """A loop message that cannot be read: zero force at once (as a non-finite one)."""
        self.input.renderer.clear()
        self.safety.reject(f'rejected: {why}')
        self.get_logger().warning(f'{why}: applying zero force', throttle_duration_sec=1.0)

    def _arrived(self, why: str, stamp: int) -> None:
        """Latency of every command (zoh) / model (local_model) answering a known pose, taken or
        refused as stale (so the figures are not cut at the age limit); the measurement window
        opens at the first one taken."""
        script = getattr(self.device, 'script', None)
        held = script.held if self.native is None else self.native.held
        if isinstance(script, HeldScript) and held and (why == OK or why.endswith(STALE)) \
                and (self.release_gate is None or self.release_gate()):
            script.release()  # a force source answers our poses (late or not): start the palpation
            if self.native is not None:
                self.native.release()
        if why == OK and self.first_command is None:
            now = time.monotonic()
            self.first_command = now
            self._cpu0 = time.process_time()  # the process's CPU over the window (summary)
            # the trace and the model statistics measure the loop from the first command on
            self.input.reset_stats()
            if self.servo.trace is not None:
                self.servo.trace.clear()
            if self.run_duration > 0:  # so do the loop statistics
                self.servo.stats.reset()
        if self.first_command is not None and (why == OK or why.endswith(STALE)):
            self.servo.stats.latency((time.time_ns() - stamp) * 1e-9)

    def ready_condition(self) -> tuple[bool, str]:
        """Ready (see nodes/session.py) once a valid force command arrived."""
        return self.first_command is not None, ('force source seen' if self.first_command
                                                is not None else 'no force command yet')

    def summary(self) -> dict:
        s = self.servo.stats.summary()
        ss = self.safety.stats
        s.update(commands=ss.commands, rejected_nonfinite=ss.rejected_nonfinite,
                 rejected_frame=ss.rejected_frame, watchdog_trips=ss.watchdog_trips,
                 watchdog_trips_in_contact=ss.watchdog_trips_in_contact,
                 clamped=ss.clamped, servo_errors=self.servo.errors,
                 servo_scheduling=self.servo.scheduling, loop_windows=self.health.windows,
                 loop_windows_behind=self.health.behind,
                 **self.input.summary())
        if self.native is not None:
            s.update(trace_rows_lost=self.native.trace_lost,
                     bridge_rate_hz=self.native.bridge_gaps.summary()['rate_hz'])
        if self.first_command is not None:  # CPU of this process (all its threads) / wall time
            wall = time.monotonic() - self.first_command
            s['process_cpu_pct'] = (round(100.0 * (time.process_time() - self._cpu0) / wall, 1)
                                    if wall > 0 else None)
        return s

    def close(self) -> None:
        """Stop the servo thread; the device is left at zero force."""
        if self.started and (self.servo.running or self.safety.enabled):
            self.servo.stop()
        for sub, _ in self._polled:
            sub.destroy()
        if self.trace_path and self.servo.trace is not None:
            self._save_trace()
        if self.run_duration > 0:
            print(json.dumps({'falcon_driver_stats': _jsonable(self.summary())}), flush=True)


    def _save_trace(self) -> None:
        """The servo ticks in the tissue frame (position, applied force) with the statistics."""
        rows = self.servo.trace.arrays()
        m = self.mapping
        rows[:, 1:4] = np.asarray(m.offset) + m.scale * rows[:, 1:4]
        rows[:, 4:7] /= m.force_scale
        save_trace(self.trace_path, rows, stats=_jsonable(self.summary()),
                   status_names=list(STATUS_NAMES), max_force=self.params['max_force'] /
                   m.force_scale, frame_id=self.frame_id,
                   ticks_dropped=self.servo.trace.dropped,  # the oldest, beyond the ring's bound
                   period=1.0 / self.params['rate'],
                   # the ticks' monotonic times onto the wall clock a bag's receive times use
                   realtime_minus_monotonic_s=time.time() - time.monotonic(),
                   model_hold_time=self.params['model_hold_time'],
                   model_hold_radius=self.params['model_hold_radius'],
                   model_blend_time=self.params['model_blend_time'],
                   passivity_window=self.params['passivity_window'])
        self.get_logger().info(f'servo tick trace: {len(rows)} ticks -> {self.trace_path}'
                               + (f' (the oldest {self.servo.trace.dropped} dropped: bounded)'
                                  if self.servo.trace.dropped else ''))
        self.servo.trace = None


def _jsonable(d: dict) -> dict:
    return {k: (None if isinstance(v, float) and not math.isfinite(v) else v) for k, v in d.items()}


def main(args=None) -> None:
    raise SystemExit(run_node(FalconDriver, args))


if __name__ == '__main__':
    main()
