"""``force_server``: contact in, force command out (:class:`haptic_anfis.anfis.ForceModel`).

Subscribes to ``contact`` (``sensor_msgs/JointState``, see :mod:`haptic_anfis.nodes.interfaces`),
evaluates the Fx, Fy, Fz ANFIS models on the compiled path (compiled and warmed when the model is
loaded, before the first message) and publishes ``falcon/servo_cf`` (``geometry_msgs/
WrenchStamped``, tissue frame) with the contact's stamp: zero when not in contact (or on a malformed
contact / NaN input). The service ``~/reload`` (``std_srvs/Trigger``) re-reads ``model_path``: the
new model replaces the old in one reference swap between two messages (a load takes ~1-2 ms); a
bad file keeps the old model and the response says why.
"""
from __future__ import annotations

import time
from pathlib import Path

from geometry_msgs.msg import WrenchStamped
from rclpy.node import Node
from sensor_msgs.msg import JointState
from std_srvs.srv import Trigger

from ..anfis import ForceModel
from ..dataset import DATA_DIR
from . import interfaces as ifc
from ._case import CASE_PARAMS, apply_case, declare_case  # noqa: F401 (CASE_PARAMS: in config)
from ._common import LOOP_QOS, Param, declare_parameters, positive, run_node

DEFAULT_MODEL = DATA_DIR / 'default_model.json'

PARAMS = [
    Param('model_path', '', "ANFIS model file (JSON) ('' = the shipped default model); re-read "
          'by ~/reload'),
    Param('frame_id', 'tissue', 'frame of the published force (the tissue frame)'),
    Param('case_ramp', 0.5, 'after a case switch the force ramps from 0 to the model force over '
          'this long [s] (the new surface may put the probe deeper at once)', positive),
]


def load_model(p: dict) -> tuple[Path, ForceModel]:
    """(path, model) from the node's parameter values ``p`` (also used by the bag re-simulation and
    the reload service). ``ForceModel.load`` compiles and warms the real-time path, so the first
    contact pays no compilation. Raises ModelFileError (a ValueError) on a bad file."""
    path = Path(p['model_path']) if p['model_path'] else DEFAULT_MODEL
    return path, ForceModel.load(path)


def force_from_contact(model: ForceModel, v) -> tuple[float, float, float, str | None]:
    """(fx, fy, fz, error or None) for the contact message values ``v``: the model's force in
    contact, zero when not in contact or on a malformed / non-finite contact (with the reason)."""
    if len(v) != len(ifc.CONTACT_FIELDS):
        return 0.0, 0.0, 0.0, (f'contact message with {len(v)} values, expected '
                               f'{len(ifc.CONTACT_FIELDS)} ({", ".join(ifc.CONTACT_FIELDS)})')
    if v[ifc.I_IN_CONTACT] > 0.5 and v[ifc.I_DEPTH] > 0.0:
        try:
            fx, fy, fz = model.predict_one(v[0], v[1], v[2], v[ifc.I_DEPTH])
        except ValueError as exc:  # NaN/Inf in the contact: zero force
            return 0.0, 0.0, 0.0, str(exc)
        return fx, fy, fz, None
    return 0.0, 0.0, 0.0, None


class ForceServer(Node):
    def __init__(self, name: str = 'force_server', **kw):
        super().__init__(name, **kw)
        p = self.own_params = declare_parameters(self, PARAMS)
        self._ramp_t0: float | None = None  # monotonic time of the last case switch
        p = self.params = apply_case(p, declare_case(self, self.switch_case))
        self.model_path, self.model = load_model(p)  # ModelFileError (a ValueError) -> exit 1
        self.pub = self.create_publisher(WrenchStamped, ifc.TOPIC_COMMAND, LOOP_QOS)
        self.sub = self.create_subscription(JointState, ifc.TOPIC_CONTACT, self._on_contact,
                                            LOOP_QOS)
        self.srv = self.create_service(Trigger, '~/reload', self._on_reload)
        self._msg = WrenchStamped()
        self._msg.header.frame_id = p['frame_id']
        self.n_contacts = self.n_forces = self.n_bad = self.reloads = 0
        self.max_force = 0.0
        self.get_logger().info(f'model {self.model_path} ({self._describe()})')

    def _describe(self) -> str:
        st = '/'.join('-'.join(map(str, s)) for s in self.model.structures_)
        return f'structures {st}'

    def _on_contact(self, msg: JointState) -> None:
        self.n_contacts += 1
        out = self._msg
        out.header.stamp = msg.header.stamp
        f = out.wrench.force
        model = self.model
        fx, fy, fz, error = (force_from_contact(model, msg.position) if model is not None
                             else (0.0, 0.0, 0.0, None))  # no model: mid case switch
        if self._ramp_t0 is not None and (fx or fy or fz):  # after a case switch: ramp up
            now = time.monotonic()
            if self._ramp_t0 < 0.0:  # the first force since the switch starts the ramp: 0 N
                self._ramp_t0 = now
            k = (now - self._ramp_t0) / self.params['case_ramp']
            if k >= 1.0:
                self._ramp_t0 = None
            else:
                fx, fy, fz = k * fx, k * fy, k * fz
        if error is not None:
            self._bad(error)
        elif fx or fy or fz:
            self.n_forces += 1
            n = (fx * fx + fy * fy + fz * fz) ** 0.5
            if n > self.max_force:
                self.max_force = n
        f.x, f.y, f.z = fx, fy, fz
        self.pub.publish(out)

    def _bad(self, why: str) -> None:
        self.n_bad += 1
        self.get_logger().warning(f'bad contact ({why}): zero force', throttle_duration_sec=1.0)

    def reload(self) -> tuple[bool, str]:
        """Load ``model_path`` again; keep the current model if that fails."""
        t0 = time.perf_counter()
        try:
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
