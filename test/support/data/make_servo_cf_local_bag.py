"""Write the wire-format fixture ``servo_cf_local_b517df5/``: 60 poses of a press over the shipped
surface through the contact detector and the force server's per-message code, recorded as the
``contact`` and ``falcon/servo_cf_local`` messages they publish (every 7th contact cut to the older
9-value layout). The committed bag was written by main at b517df5, before the pipeline moved out of
the node modules (issue 28), with this same script importing the old names; test_pipeline.py checks
that today's code decodes it and answers its contacts with the same local models. Re-running it
rewrites the fixture with the current code (only when the format changes on purpose)::

    .venv/bin/python test/support/data/make_servo_cf_local_bag.py test/support/data/servo_cf_local_b517df5
"""
import sys
from pathlib import Path

import numpy as np

from haptic_anfis import interfaces as ifc
from haptic_anfis.pipeline import contact as pc, force as pf
from haptic_anfis.bag.topics import JOINT_STATE_TYPE, absolute, typestore
from haptic_anfis.bag.writer import BagWriter
from haptic_anfis.nodes import cdr, contact_detector as cd, force_server as fs
from haptic_anfis.nodes.parameter_files import resolve_parameters

out = Path(sys.argv[1])
tracker = pc.make_tracker(resolve_parameters(cd.PARAMS, 'contact_detector'))
_, model = pf.load_model(resolve_parameters(fs.PARAMS, 'force_server'))
ts = typestore()
JS, H, T = (ts.types[t] for t in ('sensor_msgs/msg/JointState', 'std_msgs/msg/Header',
                                  'builtin_interfaces/msg/Time'))
lmw = cdr.JointStateWriter('tissue', ifc.LOCAL_MODEL_FIELDS, len(ifc.LOCAL_MODEL_FIELDS))
w = BagWriter(out, custom_data={'note': 'contact + servo_cf_local (i28 wire-format fixture)'})
w.add_topic(absolute(ifc.TOPIC_CONTACT), JOINT_STATE_TYPE)
w.add_topic(absolute(ifc.TOPIC_LOCAL_MODEL), JOINT_STATE_TYPE)
t0 = 1_763_900_000_000_000_000
for i, s in enumerate(np.linspace(0.0, 1.0, 60)):
    p = (0.035 + 0.02 - 0.032 * s, 0.01 * np.sin(6 * s), 0.01 * np.cos(5 * s))
    v, c, _ = pc.contact_values(tracker, 'tissue', 'tissue', p)
    eff = pc.approach_values(tracker, c, p, 0.005)
    if i % 7 == 3:  # the older 9-value layout (no normal)
        v, eff = v[:ifc.N_CONTACT_V1], []
    stamp = t0 + i * 1_000_000
    msg = JS(header=H(stamp=T(sec=stamp // 10**9, nanosec=stamp % 10**9), frame_id='tissue'),
             name=list(ifc.CONTACT_FIELDS[:len(v)]), position=np.array(v, dtype=np.float64),
             velocity=np.zeros(0), effort=np.array(eff, dtype=np.float64))
    w.write(absolute(ifc.TOPIC_CONTACT), bytes(ts.serialize_cdr(msg, JOINT_STATE_TYPE)), stamp)
    _, lm, _ = pf.local_model_from_contact(model, v, approach=eff)
    w.write(absolute(ifc.TOPIC_LOCAL_MODEL), lmw.pack(stamp, lm), stamp + 1000)
w.close()
print('written', out)
