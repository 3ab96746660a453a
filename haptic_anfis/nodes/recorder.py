"""``recorder``: record topics to a rosbag2 bag (MCAP storage, metadata version 9).

Reads its topics as serialized CDR bytes (no deserialisation) without an executor callback per
message: a taker thread empties every subscription's reader each ``take_period`` and hands each
message with its DDS receive time (system clock) to :class:`haptic_anfis.bag.BagWriter`, whose own
thread writes the file. (Per-message callbacks on the executor thread cost the one-process haptic
graph of ``haptic-anfis sim --record`` its rate: its executor thread ran at ~94 % of a core.)
Types: the package's topics are known up front (subscribed at once, before their publishers
appear); any other topic is subscribed once the graph shows its type (checked every
``discovery_period``). Ctrl-C / SIGTERM write everything received, the MCAP summary and
metadata.yaml; after a crash at most ``flush_period`` s (plus the queue) are lost, and
``haptic-anfis bag recover PATH`` rebuilds the bag.

A write failure (disk full, file-size limit, I/O error) is logged at ERROR the moment the writer
thread meets it; the bag is sealed up to its last whole chunk (``bag info`` opens it). With
``fallback_output_dir`` the recording continues in a bag of the same name there; without, the node
stays up without recording (the haptic session goes on; a restart would meet the same full disk)
and exits with status 1 when stopped.
"""
from __future__ import annotations

import json
import signal
import threading
import time

from rcl_interfaces.msg import SetParametersResult
from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy

from ..bag import BagError, BagWriter
from ..bag.reader import RECORDER_MARK
from ..bag.segment import COMPRESSIONS
from ..bag.topics import DEFAULT_TOPICS, KNOWN_TYPES
from ..cases import CaseError, library
from ..cases.force_mapping import case_force_mapping
from ._case import declare_case_parameters, requested_case
from .base import HapticNode
from .parameters import CASE_PARAMS  # noqa: F401 (a case node: the registry reads it here)
from .parameters import Param, declare_parameters, positive
from .polled import PolledSubscription
from .runtime import message_class, run_node
from .session import inputs_matched

#: Topics never recorded with ``all_topics`` (ROS infrastructure, as ``ros2 bag record -a``).
IGNORED = ('/rosout', '/parameter_events')

PARAMS = [
    Param('output', '', "bag directory to create ('' = session_YYYYmmdd-HHMMSS in the working "
          'directory); it must not exist yet'),
    Param('topics', list(DEFAULT_TOPICS), 'topics to record (relative names resolve in the node '
          'namespace); default: pose, contact, force command, buttons, marks'),
    Param('all_topics', False, 'also record every other topic that appears in the graph '
          '(except /rosout and /parameter_events)'),
    Param('flush_period', 0.5, 'close and flush the pending MCAP chunk at least this often [s]: '
          'a crash loses at most this much', positive),
    Param('chunk_size', 262144, 'close the pending MCAP chunk once it holds this many bytes',
          positive),
    Param('max_queue', 200000, 'messages allowed to wait for the writer thread; beyond that new '
          'ones are dropped and counted', positive),
    Param('qos_depth', 1000, 'history depth of the (reliable) recording subscriptions', positive),
    Param('fallback_output_dir', '', "if writing the bag fails (disk full, I/O error): continue "
          "in a new bag of the same name in this directory ('' = stop recording, stay up, exit "
          'status 1 at the end)'),
    Param('compression', 'zstd', 'MCAP chunk compression: zstd (level 1; 3.6x smaller, releases '
          'the GIL), lz4 (2.9x; stalls other threads, the servo thread too, for much of its '
          'compress time) or none', lambda v: None if v in COMPRESSIONS else
          f'expected one of {", ".join(COMPRESSIONS)}'),
    Param('discovery_period', 0.5, 'how often the graph is checked for topics still to subscribe '
          '[s]', positive),
    Param('take_period', 0.005, 'how often the received messages are taken from the '
          'subscriptions and queued for the writer [s] (each keeps its DDS receive time)',
          positive),
]


def default_output() -> str:
    return time.strftime('session_%Y%m%d-%H%M%S')


def _case_label(name: str, seed: int) -> str:
    """The case the loop nodes run for ``case`` / ``random_case_seed`` (as
    :func:`haptic_anfis.cases.resolve_case` draws it; a draw that fails: 'unknown'), by name:
    '' -> 'default'.

    Raises:
        CaseError: ``name`` is not a case of the library.
    """
    if seed >= 0:
        try:
            return library().random(seed).name
        except CaseError:   # no case ready: the loop nodes refuse the draw too
            return 'unknown'
    if name:
        library().get(name)   # CaseError for a name the library does not have
    return name or 'default'


def _force_mapping_data(label: str) -> dict[str, str]:
    """The bag's ``force_mapping`` custom data for the case ``label``: the tissue -> device force
    scale a session of that case renders unless its ``force_scale`` is set
    (:mod:`haptic_anfis.cases.force_mapping`), as JSON; {} for an unknown case or one without a
    dataset. After a case switch it is the mapping of the case switched to (the one in force
    at the bag's end; ``case`` lists the session's cases in order)."""
    try:
        m = case_force_mapping(library().get(label))
    except CaseError:
        return {}
    return {'force_mapping': json.dumps(m.as_dict())}


class Recorder(HapticNode):
    """Parameters in :data:`PARAMS` and the session's case (``case`` / ``random_case_seed``, as
    the loop nodes take them), which the bag's custom data ``case`` names for ``exam report``:
    the case names in the order the session switched to them, comma-separated (a blind
    session's too). Neither parameter given: the recorder does not know the case (the nodes'
    own files) and writes none until a switch (then 'unknown, NAME'). The case is only a label
    here: a case whose files are missing or whose scene changed is still named (the loop nodes
    refuse it), so that recording never fails for it. ``topics`` / ``output`` arguments
    override the parameters (used by ``haptic-anfis sim --record``); ``custom_data`` adds to
    the bag's custom data (``exam run``: the scene file)."""

    def __init__(self, name: str = 'recorder', *, topics=None, output: str | None = None,
                 custom_data: dict[str, str] | None = None, **kw):
        super().__init__(name, **kw)
        p = self.params = declare_parameters(self, PARAMS)
        declare_case_parameters(self)   # writable: the session's case switches follow
        name = self.get_parameter('case').value
        seed = self.get_parameter('random_case_seed').value
        given = bool(name) or seed >= 0
        #: the cases of the session, in order (the first 'unknown' when none was given)
        self.cases = [_case_label(name, seed)] if given else ['unknown']
        self.add_on_set_parameters_callback(self._on_set_case)
        self.output = output or p['output'] or default_output()
        wanted = list(topics) if topics is not None else p['topics']
        self.wanted = [self.resolve_topic_name(t) for t in wanted]
        self.all_topics = p['all_topics']
        self.qos = QoSProfile(depth=p['qos_depth'], history=HistoryPolicy.KEEP_LAST,
                              reliability=ReliabilityPolicy.RELIABLE)
        self.exit_code = 0
        if threading.current_thread() is threading.main_thread():
            # a file-size limit (ulimit -f) would kill the process silently with SIGXFSZ; ignored,
            # the write fails with EFBIG and is reported like a full disk
            signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
        self.writer = BagWriter(self.output, flush_period=p['flush_period'],
                                chunk_size=p['chunk_size'], max_queue=p['max_queue'],
                                custom_data={'recorder': RECORDER_MARK,
                                             **({'case': self.cases[0]} if given else {}),
                                             **_force_mapping_data(self.cases[0]),
                                             **(custom_data or {})},
                                compression=p['compression'],
                                fallback_dir=p['fallback_output_dir'] or None,
                                on_error=self._on_write_error)
        self.subs: dict[str, PolledSubscription] = {}
        self._closed = False
        self._stop = threading.Event()
        self._discover()
        self.timer = self.create_timer(p['discovery_period'], self._discover)
        self._taker = threading.Thread(target=self._take_loop, args=(p['take_period'],),
                                       name='recorder-take', daemon=True)
        self._taker.start()
        self.get_logger().info(f'recording to {self.output}: {", ".join(self.wanted)}'
                               + (' + every other topic' if self.all_topics else ''))

    def _on_set_case(self, params) -> SetParametersResult:
        """The session switched its case (a writable parameter set): the bag says so."""
        try:
            asked = requested_case(self, params)
            label = None if asked is None else _case_label(*asked)
        except CaseError as exc:   # a wrong type, a name the library does not have
            return SetParametersResult(successful=False, reason=str(exc))
        if label is not None and label != self.cases[-1]:
            self.cases.append(label)
            self.writer.set_custom_data('case', ', '.join(self.cases))
            # the mapping in force from now on (the page sets the driver's scale with the case)
            self.writer.set_custom_data('force_mapping',
                                        _force_mapping_data(label).get('force_mapping', ''))
        return SetParametersResult(successful=True)

    def _discover(self) -> None:
        graph = dict(self.get_topic_names_and_types())
        names = list(self.wanted)
        if self.all_topics:
            names += [t for t in graph if t not in IGNORED and t not in names]
        for topic in names:
            if topic in self.subs:
                continue
            types = graph.get(topic) or []
            msgtype = types[0] if types else KNOWN_TYPES.get(topic)
            if msgtype is None:
                continue  # not seen yet; try again at the next discovery
            if len(types) > 1:
                self.get_logger().warning(f'{topic} has several types {types}: recording {msgtype}')
            try:
                cls = message_class(msgtype)
                self.writer.add_topic(topic, msgtype)
            except ValueError as exc:
                self.get_logger().error(f'cannot record {topic}: {exc}', once=True)
                continue
            self.subs[topic] = PolledSubscription(self, cls, topic, self.qos)

    def _take_loop(self, period: float) -> None:
        while not self._stop.wait(period):
            self._take_all()

    def _take_all(self) -> None:
        """Queue every message waiting in the subscriptions (taker thread, and once at close)."""
        write = self.writer.write
        for topic, sub in list(self.subs.items()):  # the executor thread may add topics
            while True:
                try:
                    got = sub.take_with_info()
                except Exception as exc:  # noqa: BLE001 (a reader gone at shutdown)
                    self.get_logger().warning(f'taking {topic} failed: {exc!r}',
                                              throttle_duration_sec=5.0)
                    break
                if got is None:
                    break
                data, info = got
                write(topic, data, info.get('received_timestamp') or time.time_ns())

    def ready_condition(self) -> tuple[bool, str]:
        """Ready (nodes/session.py) once every wanted topic has a publisher."""
        return inputs_matched(self, self.wanted)

    def _on_write_error(self, message: str) -> None:
        """From the writer thread, at the failure: say it now, once. Without a fallback the
        node stays up without recording (a recording failure never stops the haptic session,
        and a restarted recorder would only meet the same full disk); it exits with status 1
        when the session stops it."""
        if not hasattr(self, 'writer') or self.writer.failed:
            self.exit_code = 1
            self._stop.set()  # no more taking: nothing can be written
            message += '; the session goes on without recording'
        self.get_logger().error(message)

    def summary(self) -> dict:
        return {'output': str(self.output), 'topics': sorted(self.subs), **self.writer.stats()}

    def close(self) -> None:
        """Write everything received, the summary and metadata.yaml (idempotent)."""
        if self._closed:
            return
        self._closed = True
        self._stop.set()
        if self._taker.is_alive():
            self._taker.join(timeout=2.0)
        self._take_all()  # what arrived since the last take
        for s in self.subs.values():
            s.destroy()
        try:
            self.writer.close()
        except BagError:  # a write failure, reported when it happened (ERROR log)
            self.exit_code = 1
        s = self.writer.stats()
        where = ' + '.join(s['bags'])
        msg = (f"recorded {s['written']} messages to {where}"
               + (f" ({s['dropped']} dropped: queue full)" if s['dropped'] else '')
               + (f" ({s['lost']} lost after the write failure)" if s['lost'] else ''))
        (self.get_logger().error if s['failed'] else self.get_logger().info)(msg)

    def destroy_node(self):
        self.close()
        return super().destroy_node()


def main(args=None) -> None:
    raise SystemExit(run_node(Recorder, args))


if __name__ == '__main__':
    main()
