"""The per-message pipeline of the haptic loop, ROS-free: pose -> contact values -> force and local
force model values.

One pose of the probe tip goes through two stages, each a plain function on plain Python values,
in its own module so a node loads only its stage (the force server does not load the mesh
library, the contact detector does not load the force model):

1. **Contact** (:mod:`.contact`, what the ``contact_detector`` node runs per
   ``falcon/measured_cp``): ``contact_values`` advances a :class:`~haptic_anfis.contact.
   ContactTracker` to the pose and returns the contact message's ``position`` values
   (:data:`~haptic_anfis.interfaces.CONTACT_FIELDS`); ``approach_values`` its ``effort`` values
   (the surface ahead of a free probe, :data:`~haptic_anfis.interfaces.APPROACH_FIELDS`);
   ``make_tracker`` / ``load_surface`` build the tracker from the node's parameter values.
2. **Force** (:mod:`.force`, what the ``force_server`` node runs per ``contact``):
   ``force_from_contact`` (the ANFIS model's force, zero-order hold) or
   ``local_model_from_contact`` (the force and the local force model F0, p0, K = dF/dp the driver
   renders at every servo tick, as the ``falcon/servo_cf_local`` message's values, encoded by
   :func:`haptic_anfis.device.local_model.model_values`; free probe: ``approach_model``);
   ``load_model`` loads the model from the node's parameter values.

:func:`.replay.pose_to_force` chains the two for offline users (the bag re-simulation
:mod:`haptic_anfis.nodes.resim`, ``haptic-anfis loop`` replays, tests and benchmarks), so a replay
runs exactly the nodes' code. The builders take a dict with the nodes' parameter names (the nodes
declare and resolve them).

Contact values are read in either layout, the current 12 values or the older 9 (no normal:
:func:`.force.contact_normal` then gives -direction), checked by
:func:`haptic_anfis.interfaces.is_contact_values`.

Units: metres, newtons, N/m; tissue frame. Bad input (a pose with NaN/Inf or in another frame, a
malformed contact, a non-finite model output) never raises in the per-message functions: it gives
"no contact" / zero force and the reason as a string, which the caller logs; the loop keeps
running.
"""
__all__ = ['contact', 'force', 'replay']
