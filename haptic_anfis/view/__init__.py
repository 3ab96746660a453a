"""The trainee's screen in a browser (no ROS): the breast with the dent under the probe, the
coverage painted per pressure level, the force gauge and cue, and the debrief of a session
(lesions revealed, marks, path, score, a replay scrubber); and the instructor's console on a page
of its own behind a token; served by ``viser`` behind a door that checks who connects.

- :mod:`.scene`: colours, camera framing, probe orientation (plain arrays).
- :mod:`.gauge`: the force gauge's bands and the trainee's cue.
- :mod:`.debrief`: a scored session as the page shows it at any replay time.
- :mod:`.app`: :class:`ViewApp`, the trainee's page.
- :mod:`.console`: :class:`~.console.ConsoleApp`, the instructor's console; :mod:`.curves` its
  learning curves.
- :mod:`.doors`: Host / Origin / token checks in front of every viser server, one log line per
  malformed message; :mod:`.escape`: user texts shown as text.
- :mod:`.build`: a case's or a bag's page.
- :mod:`.browser`: headless chromium screenshots for tests, benches and the docs.
"""
from .app import BLIND, ViewApp, ViewError, check_port, trainee_history
from .debrief import Debrief, lesion_status, panel_numbers
from .gauge import Gauge, gauge
from .scene import SkinPaint, frame_camera, probe_quaternion

__all__ = ['BLIND', 'Debrief', 'Gauge', 'SkinPaint', 'ViewApp', 'ViewError', 'check_port',
           'frame_camera', 'gauge', 'lesion_status', 'panel_numbers', 'probe_quaternion',
           'trainee_history']
