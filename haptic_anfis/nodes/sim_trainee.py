"""The simulated trainee's senses (used by ``haptic-anfis exam run``; sim only, no parameters).

Pairs each in-contact ``contact`` message with the force command stamped with it (the wrench topic:
what the trainee feels) and hands (contact point, depth, |F|) to a
:class:`~haptic_anfis.exam.trainee.TraineeController`; when the search script is over, asks it to
decide where to mark (off the servo thread, 10 Hz timer).
"""
from __future__ import annotations

import math

from geometry_msgs.msg import WrenchStamped
from sensor_msgs.msg import JointState

from .. import interfaces as ifc
from .runtime import stamp_ns
from .base import HapticNode
from .examiner import SAMPLE_QOS


#: contacts waiting for their force (stamp -> sample); the oldest go first past this many (5 s of
#: 1 kHz contacts): a bound, not a clear-all, so a burst of late forces on a loaded machine
#: leaves the newest contacts waiting
MAX_PENDING = 5000


class SimTrainee(HapticNode):
    def __init__(self, controller, name: str = 'sim_trainee', **kw):
        super().__init__(name, **kw)
        self.controller = controller
        self._pending: dict[int, tuple] = {}
        self.create_subscription(JointState, ifc.TOPIC_CONTACT, self._on_contact, SAMPLE_QOS)
        self.create_subscription(WrenchStamped, ifc.TOPIC_COMMAND, self._on_force, SAMPLE_QOS)
        self.create_timer(0.1, self._tick)
        self.felt = 0

    def _on_contact(self, msg: JointState) -> None:
        v = msg.position
        if ifc.is_contact_values(v) and v[ifc.I_IN_CONTACT] > 0.5:
            pending = self._pending
            while len(pending) >= MAX_PENDING:   # forces lost: forget the oldest, do not grow
                del pending[next(iter(pending))]
            pending[stamp_ns(msg.header.stamp)] = (v[0], v[1], v[2], v[ifc.I_DEPTH])

    def _on_force(self, msg: WrenchStamped) -> None:
        c = self._pending.pop(stamp_ns(msg.header.stamp), None)
        if c is not None:
            f = msg.wrench.force
            self.controller.feel(c[:3], c[3], math.sqrt(f.x * f.x + f.y * f.y + f.z * f.z))
            self.felt += 1

    def _tick(self) -> None:
        if self.controller.search_over and self.controller.detections is None:
            found = self.controller.decide()
            self.get_logger().info(f'search over after {self.felt} felt samples: '
                                   f'{len(found)} suspected lump(s)' + ''.join(
                                       f'; ({d.y * 1e3:.1f}, {d.z * 1e3:.1f}) mm '
                                       f'+{100 * d.excess:.0f} %' for d in found))
