"""``force_server``: contact in, force command out (:class:`haptic_anfis.anfis.ForceModel`).

Subscribes to ``contact`` (``sensor_msgs/JointState``, see :mod:`haptic_anfis.interfaces`),
evaluates the Fx, Fy, Fz ANFIS models on the compiled path (compiled and warmed when the model is
loaded, before the first message) and publishes ``falcon/servo_cf`` (``geometry_msgs/
WrenchStamped``, tissue frame) with the contact's stamp: zero when not in contact (or on a malformed
contact / NaN input), and with it ``falcon/servo_cf_local`` (``sensor_msgs/JointState``, layout
in :mod:`haptic_anfis.interfaces`): the local force model at the contact — F0, p0 and the
stiffness K = dF/dp through the contact geometry — that the falcon driver renders at every servo
tick. The service ``~/reload`` (``std_srvs/Trigger``) re-reads ``model_path``: the new model
replaces the old in one reference swap between two messages (a load takes ~1-2 ms); a bad file
keeps the old model and the response says why.

The per-message work is :mod:`haptic_anfis.pipeline.force` (``local_model_from_contact``,
``force_from_contact``, ``load_model``); this node wires it to the topics, the case switch, the
ramp after a switch and the reload service.
"""
from __future__ import annotations

import time

from geometry_msgs.msg import WrenchStamped
from sensor_msgs.msg import JointState
from std_srvs.srv import Trigger

from ..device.local_model import no_model
from ..realtime.scheduling import off_realtime
from ..pipeline.force import force_from_contact, load_model, local_model_from_contact
from . import cdr
from .. import interfaces as ifc
from ._case import apply_case, declare_case
from .parameters import CASE_PARAMS  # noqa: F401 (a case node: the registry reads it here)
from .parameters import Param, declare_parameters, positive
from .runtime import LOOP_QOS, run_node, set_stamp, stamp_ns
from .base import HapticNode

PARAMS = [
    Param('model_path', '', "ANFIS model file (JSON) ('' = the shipped default model); re-read "
          'by ~/reload'),
    Param('frame_id', 'tissue', 'frame of the published force (the tissue frame)'),
    Param('publish_local_model', True, 'also publish the local force model (F0, p0, K) on '
          'falcon/servo_cf_local with every force (the driver renders it at every servo tick)'),
    Param('case_ramp', 0.5, 'after a case switch the force ramps from 0 to the model force over '
          'this long [s] (the new surface may put the probe deeper at once)', positive),
]


class ForceServer(HapticNode):
    def __init__(self, name: str = 'force_server', **kw):
        super().__init__(name, **kw)
        p = self.own_params = declare_parameters(self, PARAMS)
        self._ramp_t0: float | None = None  # monotonic time of the last case switch
        p = self.params = apply_case(p, declare_case(self, self.switch_case))
        self.model_path, self.model = load_model(p)  # ModelFileError (a ValueError) -> exit 1
        self.pub = self.create_publisher(WrenchStamped, ifc.TOPIC_COMMAND, LOOP_QOS)
        # raw bytes in (nodes/cdr.py): rclpy's message objects cost tens of µs of GIL per contact
        self.sub = self.create_subscription(JointState, ifc.TOPIC_CONTACT, self._on_contact,
                                            LOOP_QOS, raw=True)
        self.srv = self.create_service(Trigger, '~/reload', self._on_reload)
        self.frame_id = p['frame_id']
        self._msg = WrenchStamped()
        self._msg.header.frame_id = p['frame_id']
        self.pub_lm = None
        if p['publish_local_model']:
            self.pub_lm = self.create_publisher(JointState, ifc.TOPIC_LOCAL_MODEL, LOOP_QOS)
            # published as serialized bytes (the same JointState on the wire, ~10x cheaper)
            self._lm = cdr.JointStateWriter(p['frame_id'], ifc.LOCAL_MODEL_FIELDS,
                                            len(ifc.LOCAL_MODEL_FIELDS))
        self.n_contacts = self.n_forces = self.n_bad = self.reloads = 0
        self.max_force = 0.0
        self.get_logger().info(f'model {self.model_path} ({self._describe()})')

    def _describe(self) -> str:
        st = '/'.join('-'.join(map(str, s)) for s in self.model.structures_)
        return f'structures {st}'

    def _on_contact(self, msg: bytes | JointState) -> None:
        """One contact (serialized bytes from the subscription, or a JointState)."""
        self.n_contacts += 1
        if isinstance(msg, bytes):
            try:
                stamp, _, position, effort = cdr.read_joint_state(msg)
            except ValueError as exc:  # unreadable: nothing to answer (no stamp to answer it)
                self._bad(str(exc))
                return
        else:
            stamp, position, effort = stamp_ns(msg.header.stamp), msg.position, msg.effort
        out = self._msg
        set_stamp(out.header.stamp, stamp)
        f = out.wrench.force
        model = self.model
        values = None
        if model is None:  # mid case switch: no force (and a depth-0 model: the driver renders 0)
            fx = fy = fz = 0.0
            error = None
            values = no_model()
        elif self.pub_lm is not None:
            (fx, fy, fz), values, error = local_model_from_contact(model, position,
                                                                   approach=effort)
        else:
            fx, fy, fz, error = force_from_contact(model, position)
        k = self._case_ramp(bool(fx or fy or fz))
        if k is not None:  # after a case switch: force and local model (F0, K) scaled by k
            fx, fy, fz = k * fx, k * fy, k * fz
            if values is not None:
                values[ifc.LM_F0] = [k * c for c in values[ifc.LM_F0]]
                values[ifc.LM_K] = [k * c for c in values[ifc.LM_K]]
        lm = self._lm.pack(stamp, values) if self.pub_lm is not None else None
        if error is not None:
            self._bad(error)
        elif fx or fy or fz:
            self.n_forces += 1
            n = (fx * fx + fy * fy + fz * fz) ** 0.5
            if n > self.max_force:
                self.max_force = n
        f.x, f.y, f.z = fx, fy, fz
        self.pub.publish(out)
        if lm is not None:
            self.pub_lm.publish(lm)

    def _case_ramp(self, in_force: bool) -> float | None:
        """The factor in [0, 1) the output is scaled by while the force ramps up after a case
        switch, or None (no ramp). The first non-zero force starts the ramp (0 N then); a free
        probe's approach model (zero force) carries the factor reached so far, without starting
        or ending the ramp."""
        t0 = self._ramp_t0
        if t0 is None:
            return None
        now = time.monotonic()
        if not in_force:
            return 0.0 if t0 < 0.0 else min(1.0, (now - t0) / self.params['case_ramp'])
        if t0 < 0.0:
            self._ramp_t0 = t0 = now
        k = (now - t0) / self.params['case_ramp']
        if k >= 1.0:
            self._ramp_t0 = None
            return None
        return k

    def _bad(self, why: str) -> None:
        self.n_bad += 1
        self.get_logger().warning(f'bad contact ({why}): zero force', throttle_duration_sec=1.0)

    def reload(self) -> tuple[bool, str]:
        """Load ``model_path`` again; keep the current model if that fails."""
        t0 = time.perf_counter()
        try:
            with off_realtime():  # a load is long: never at real-time priority
                _, model = load_model(self.params)
        except Exception as exc:  # any failure keeps the old model
            msg = f'kept the previous model: cannot load {self.model_path}: {exc}'
            self.get_logger().error(msg)
            return False, msg
        self.model = model  # one reference swap: the next contact uses the new model
        self.reloads += 1
        msg = (f'loaded {self.model_path} ({self._describe()}) in '
               f'{(time.perf_counter() - t0) * 1e3:.1f} ms')
        self.get_logger().info(msg)
        return True, msg

    def switch_case(self, case) -> None:
        """Swap in the model of ``case`` (None: the own ``model_path``); zero force while it is
        swapped, then a ramp over ``case_ramp``. A bad model raises and keeps the old one."""
        params = apply_case(self.params, case, self.own_params)
        path, model = load_model(params)  # raises on a bad file: nothing changed
        self.model = None  # a contact arriving mid-swap (other thread) gets zero force
        self._ramp_t0 = -1.0  # ramp from the next contact (a slow swap must not eat the ramp)
        self.params, self.model_path = params, path
        self.model = model

    def _on_reload(self, request, response):
        response.success, response.message = self.reload()
        return response

    def summary(self) -> dict:
        return {'contacts': self.n_contacts, 'forces': self.n_forces, 'bad': self.n_bad,
                'max_model_force_N': self.max_force}


def main(args=None) -> None:
    raise SystemExit(run_node(ForceServer, args))


if __name__ == '__main__':
    main()
