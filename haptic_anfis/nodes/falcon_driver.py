"""``falcon_driver``: owns the haptic device; its 1 kHz servo tick is compiled and runs without
the interpreter lock (:mod:`haptic_anfis.device.servo_native`), in a servo process of its own by
default, with the real Falcon's USB I/O there too (:mod:`haptic_anfis.device.device_process`).

Publishes the tip pose (``falcon/measured_cp``), velocity (``falcon/measured_cv``), the force it
applies (``falcon/measured_cf``, every ``measured_cf_every`` ticks) and the buttons
(``falcon/buttons``, on change and every 100 ticks), all in the tissue frame; button 0 is the
clutch and button 1 the mark (:mod:`haptic_anfis.device.buttons`; a mark is published as
``exam/marks``, ``geometry_msgs/PointStamped`` at the probe tip). Subscribes to the force
command ``falcon/servo_cf`` (``geometry_msgs/WrenchStamped``, tissue frame) and the local force
model ``falcon/servo_cf_local`` (``sensor_msgs/JointState``, layout
:data:`haptic_anfis.interfaces.LOCAL_MODEL`). ``force_mode``: ``local_model`` renders the
newest local model at every tick's position, ``zoh`` holds the newest command. A command or
model is judged by the age of the driver's own pose it answers (its stamp), not by its arrival
(:class:`haptic_anfis.device.force_input.ForceInput`); the tick's safety rules (clamp, rate
limit, watchdog, NaN / wrong-frame rejection) zero the force whatever this node does.

This node is wiring: the loop and its parts come from the table
:data:`haptic_anfis.device.driver_loops.LOOPS` by ``backend`` and ``servo_loop``; a bridge thread
calls :meth:`FalconDriver._publish_state` for the newest tick and takes the newest command and
model from their keep-last-1 readers as raw CDR (:mod:`.polled`, :mod:`.cdr`: no rclpy message
objects on the loop's path). ``trace_path`` writes every tick for the applied-force error
(:mod:`haptic_anfis.device.force_error`).
"""
from __future__ import annotations

import json
import os
import sys
import time
from typing import Callable

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from geometry_msgs.msg import PointStamped, PoseStamped, TwistStamped, WrenchStamped
from rcl_interfaces.msg import SetParametersResult
from sensor_msgs.msg import JointState, Joy

from .. import interfaces as ifc
from ..device import WorkspaceMapping
from ..device.driver_loops import LOOPS, Hooks, hand_script, jsonable
from ..device.loop_health import LoopHealth, behind_because
from ..device.safety import OK
from ..device.stamps import STALE
from ..realtime import processes
from ..resources import config_file
from . import cdr
from .base import HapticNode
from .falcon_params import PARAMS, resolve  # PARAMS: the node's (registry, config)
from .parameters import declare_parameters, positive
from .polled import PolledSubscription
from .runtime import LOOP_QOS, run_node, set_stamp

#: the shortest time [s] between two warnings that the servo loop fell behind
WARN_EVERY = 60.0


class FalconDriver(HapticNode):
    def __init__(self, name: str = 'falcon_driver', **kw):
        super().__init__(name, **kw)
        p = self.params = resolve(declare_parameters(self, PARAMS, writable=('force_scale',)), name)
        self.servo_loop = p['servo_loop']
        if p['gil_switch_interval'] > 0:  # the bridge thread gets the GIL back sooner
            sys.setswitchinterval(p['gil_switch_interval'])
        self.frame_id = p['frame_id']
        self.mapping = WorkspaceMapping(p['workspace_scale'], tuple(p['workspace_offset']),
                                        p['force_scale'])
        # a script file that cannot be read: ValueError naming the file -> exit 1
        script, what = hand_script(p, str(config_file('palpation.yaml')))
        loop = LOOPS[p['backend'], p['servo_loop']](
            p, self.mapping, self.frame_id, script,
            Hooks(self._publish_state, self._device_lost, self._device_back))
        self.loop = loop
        self.servo, self.device, self.safety = loop.servo, loop.device, loop.safety
        self.clutch, self.input = loop.clutch, loop.input
        self.add_on_set_parameters_callback(self._on_set_force_scale)
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
        #: sim: a further condition for releasing the held hand (e.g. ``haptic-anfis sim``: the
        #: recorder in its own process has matched every loop topic); set it before the executor
        #: first spins. None = the first force command alone releases it.
        self.release_gate: Callable[[], bool] | None = None
        self.finished = False
        self.exit_code = 0
        self.trace_path = p['trace_path']
        self.get_logger().info(
            f"backend {p['backend']}, {p['rate']:.0f} Hz servo thread, max force "
            f"{p['max_force']} N, force scale {p['force_scale']:g}, watchdog "
            f"{p['watchdog_timeout'] * 1e3:.1f} ms, force "
            f"{p['force_mode']}, {what}")
        self.started = False
        self.health = LoopHealth(p['watchdog_timeout'])
        self.device_lost = False
        if p['loop_check_period'] > 0:
            self.pub_diag = self.create_publisher(DiagnosticArray, ifc.TOPIC_DIAGNOSTICS, 10)
            self.create_timer(p['loop_check_period'], self._check_loop)

    def _on_set_force_scale(self, params) -> SetParametersResult:
        """``force_scale`` set while the loop runs (a case switched live: each case has its own
        force mapping): rendered from the next tick; refused unless finite and > 0."""
        for prm in params:
            if prm.name != 'force_scale':
                continue
            s = prm.value
            if isinstance(s, bool) or not isinstance(s, (int, float)) or positive(s):
                return SetParametersResult(successful=False,
                                           reason=f'force_scale: {s!r}: expected a finite value > 0')
            self.mapping = self.loop.set_force_scale(float(s), self.params['max_stiffness'])
            self.params['force_scale'] = float(s)
            self.get_logger().info(f'force scale {s:g}')
        return SetParametersResult(successful=True)

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
        """The likely cause of a servo loop falling behind, and what to do, from how it runs
        (the servo threads' policy as the kernel has it now: rtkit may have demoted them since
        the start's scheduling line)."""
        return behind_because(self.params['backend'], processes.servo_realtime(os.getpid()),
                              self.servo.scheduling)

    def start_loop(self) -> None:
        """Start the servo loop (a real device is opened here: a FalconError / OSError). Called
        once the process has settled (:func:`~.runtime.run_node`, the one-process graph): the
        loop's bridge thread shares this process's interpreter lock, so it should not wait
        behind the rest of the process's start. Idempotent."""
        if self.started:
            return
        self.servo.start()
        self.started = True
        self.health.check(self.servo.stats.summary())  # the first window starts here
        if 'refused' in self.servo.scheduling:  # one call site per severity (rclpy)
            self.get_logger().warning(f'servo thread: {self.servo.scheduling}')
        else:
            self.get_logger().info(f'servo thread: {self.servo.scheduling}')

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
            ap, k = self._applied, 1.0 / m.force_scale
            ap.header.stamp, f = pose.header.stamp, ap.wrench.force
            f.x, f.y, f.z = force[0] * k, force[1] * k, force[2] * k
            self.pub_applied.publish(ap)
        if state.buttons != self._buttons or self._tick % 100 == 0:
            self._buttons = state.buttons
            joy = Joy(buttons=list(state.buttons))
            joy.header.stamp, joy.header.frame_id = pose.header.stamp, self.frame_id
            self.pub_buttons.publish(joy)
        if ev.mark:  # the probe tip; the examiner projects it on the surface
            mk = PointStamped()
            mk.header.stamp, mk.header.frame_id = pose.header.stamp, self.frame_id
            mk.point.x, mk.point.y, mk.point.z = x, y, z
            self.pub_mark.publish(mk)
        if self.first_command is not None and self.run_duration > 0 \
                and now - self.first_command >= self.run_duration:
            self.finished = True

    # -- the loop's inputs, as raw CDR (no rclpy message objects: GIL time per message), on the
    # bridge thread (take_in_servo_thread, the default) or the executor's -------------------
    def _on_command(self, raw: bytes) -> None:
        now = time.monotonic()
        try:
            stamp, frame, f = cdr.read_wrench_stamped(raw)
        except ValueError as exc:  # malformed: zero force, as for a non-finite command
            self._malformed(f'force command {exc}')
            return
        why = self.input.command(f, stamp, frame, now)
        if self.input.mode == 'zoh':
            self.loop.arrived(why, stamp, self.run_duration > 0, self.release_gate)
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
        why = self.input.model_values(v, stamp, frame, now)
        self.loop.arrived(why, stamp, self.run_duration > 0, self.release_gate)
        if why != OK and not (why.endswith(STALE) and self.first_command is None):
            self.get_logger().warning(f'local force model {why}', throttle_duration_sec=1.0)

    def _malformed(self, why: str) -> None:
        """A loop message that cannot be read: zero force at once (as a non-finite one)."""
        self.input.renderer.clear()
        self.safety.reject(f'rejected: {why}')
        self.get_logger().warning(f'{why}: applying zero force', throttle_duration_sec=1.0)

    @property
    def first_command(self) -> float | None:
        """Monotonic time [s] the first force command / model was taken (None: none yet)."""
        return self.loop.first_command

    def ready_condition(self) -> tuple[bool, str]:
        """Ready (see nodes/session.py) once a valid force command arrived."""
        return self.first_command is not None, ('force source seen' if self.first_command
                                                is not None else 'no force command yet')

    def summary(self) -> dict:
        return self.loop.summary(self.health)

    def close(self) -> None:
        """Stop the servo thread; the device is left at zero force."""
        if self.started and (self.servo.running or self.safety.enabled):
            self.servo.stop()
        for sub, _ in self._polled:
            sub.destroy()
        if self.trace_path and self.servo.trace is not None:  # tissue frame, with the stats
            rows = self.loop.save_trace(self.trace_path, self.mapping, self.params,
                                        self.frame_id, jsonable(self.summary()))
            self.get_logger().info(f'servo tick trace: {len(rows)} ticks -> {self.trace_path}'
                                   + (f' (the oldest {self.servo.trace.dropped} dropped: '
                                      'bounded)' if self.servo.trace.dropped else ''))
            self.servo.trace = None
        if self.run_duration > 0:
            print(json.dumps({'falcon_driver_stats': jsonable(self.summary())}), flush=True)


def main(args=None) -> None:
    raise SystemExit(run_node(FalconDriver, args))


if __name__ == '__main__':
    main()
