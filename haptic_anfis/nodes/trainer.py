"""``trainer``: trains the force model from a dataset or a recorded session, hands it to the force server.

On the service ``~/train`` (``std_srvs/Trigger``; or at start with ``train_at_start``) it trains
:class:`~haptic_anfis.anfis.ForceModel` on ``dataset_path`` (the paper's protocol,
:func:`~haptic_anfis.anfis.train_on_dataset`) on a worker thread, publishes progress lines on
``~/progress`` (``std_msgs/String``), writes ``model_path`` atomically and calls the force server's
reload service (``reload_service``). Point the force server's ``model_path`` at the same file.
``dataset_path`` is a force dataset CSV or a recorded session bag: then the in-contact pairs of
contact message and force command are the samples (:mod:`haptic_anfis.bag.training_data`).
"""
from __future__ import annotations

import threading
import time

from std_msgs.msg import String
from std_srvs.srv import Trigger

from ..anfis import train_on_dataset
from ..anfis.defaults import SHIPPED
from ..bag.training_data import load_training_data
from ..tissue.dataset import DEFAULT_DATASET
from .. import interfaces as ifc
from .parameters import Param, declare_parameters, positive
from .runtime import run_node
from .base import HapticNode


def _structure_check(v: str):
    if not v or v == 'search':
        return None
    try:
        st = tuple(int(c) for c in v.split('-'))
    except ValueError:
        st = ()
    return None if 1 <= len(st) <= 4 and min(st) >= 1 else (
        "expected '', 'search' or one MF count per ANFIS input, like '5-5-2' (y, z, depth)")


PARAMS = [
    Param('dataset_path', '', "force dataset CSV, or a recorded session bag (directory or .mcap: "
          "its in-contact contact/force-command pairs) ('' = the shipped default dataset)"),
    Param('model_path', 'haptic_anfis_model.json', 'model file to write (atomically)',
          lambda v: None if v else 'expected a file path'),
    Param('structure', '', "MF counts for all outputs, one per ANFIS input, e.g. '5-5-2' for the "
          "default (y, z, depth) inputs ('' = the shipped configuration, 'search' = structure search)",
          _structure_check),
    Param('epochs', 0, 'training epochs of every output (0 = the shipped per-output epochs, '
          'haptic_anfis/anfis/defaults.py SHIPPED)',
          lambda v: None if v >= 0 else 'expected >= 0'),
    Param('test_fraction', SHIPPED['test_fraction'], 'held-out test part of the surface points',
          lambda v: None if 0 < v < 1 else 'expected 0 < value < 1'),
    Param('seed', SHIPPED['seed'], 'seed of the splits'),
    Param('train_at_start', False, 'train once when the node starts'),
    Param('reload_service', ifc.SERVICE_RELOAD, "the force server's reload service ('' = do not "
          'call it)'),
    Param('reload_timeout', 5.0, 'seconds to wait for the reload service to appear', positive),
]


class Trainer(HapticNode):
    def __init__(self, name: str = 'trainer', **kw):
        super().__init__(name, **kw)
        self.params = declare_parameters(self, PARAMS)
        self.pub = self.create_publisher(String, '~/progress', 10)
        self.srv = self.create_service(Trigger, '~/train', self._on_train)
        rs = self.params['reload_service']
        self.client = self.create_client(Trigger, rs) if rs else None
        self._thread: threading.Thread | None = None
        self.results: list[tuple[bool, str]] = []  # (success, message) per finished run
        if self.params['train_at_start']:
            self.start_training()

    def say(self, text: str, error: bool = False) -> None:
        """Log ``text`` (at ERROR for a failure, else INFO) and publish it on ``~/progress``."""
        (self.get_logger().error if error else self.get_logger().info)(text)
        self.pub.publish(String(data=text))

    @property
    def busy(self) -> bool:
        return self._thread is not None and self._thread.is_alive()

    def start_training(self) -> tuple[bool, str]:
        if self.busy:
            return False, 'training already running'
        self._thread = threading.Thread(target=self._train, name='trainer', daemon=True)
        self._thread.start()
        return True, f"training started on {self.params['dataset_path'] or DEFAULT_DATASET}"

    def _on_train(self, request, response):
        response.success, response.message = self.start_training()
        return response

    def _train(self) -> None:
        p = self.params
        path = p['dataset_path'] or str(DEFAULT_DATASET)
        try:
            ds = load_training_data(path)
            self.say(f'dataset {path}: {len(ds)} samples')
            st = (SHIPPED['structure'] if not p['structure'] else None
                  if p['structure'] == 'search' else
                  tuple(int(c) for c in p['structure'].split('-')))
            epochs = p['epochs'] or SHIPPED['epochs']
            self.say(f"training: structure {p['structure'] or 'shipped'}, {epochs} epochs")
            t0 = time.perf_counter()
            model, _ = train_on_dataset(ds, test_fraction=p['test_fraction'], seed=p['seed'],
                                        dataset_path=path, structure=st, epochs=epochs)
            r = model.metadata_['rmse']['test']
            self.say(f'trained in {time.perf_counter() - t0:.1f} s; test RMSE Fx {r[0]:.4f}, '
                     f'Fy {r[1]:.4f}, Fz {r[2]:.4f} N')
            model.save(p['model_path'])
            self.say(f"wrote {p['model_path']}")
        except Exception as exc:
            self.say(f'training failed: {exc}', error=True)
            self.results.append((False, str(exc)))
            return
        self._request_reload()

    def _request_reload(self) -> None:
        if self.client is None:
            self.results.append((True, 'model written; no reload requested'))
            return
        if not self.client.wait_for_service(timeout_sec=self.params['reload_timeout']):
            msg = f"reload service {self.params['reload_service']} not available"
            self.say(msg, error=True)
            self.results.append((False, msg))
            return
        fut = self.client.call_async(Trigger.Request())

        def done(f):
            res = f.result()
            self.say(f'force server reload: {"ok" if res.success else "FAILED"}: {res.message}',
                     error=not res.success)
            self.results.append((res.success, res.message))
        fut.add_done_callback(done)


def main(args=None) -> None:
    raise SystemExit(run_node(Trainer, args))


if __name__ == '__main__':
    main()
