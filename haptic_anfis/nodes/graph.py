"""The whole haptic graph in ONE process: falcon_driver, contact_detector, force_server and
(optionally) visualizer on one EventsExecutor, driven by ``spin_once(timeout_sec=...)``.

Used by ``haptic-anfis sim``, the in-process tests and ``bench/bench_loop.py``. The servo loop runs
on the driver's own thread; the executor thread carries pose -> contact -> force -> driver.
"""
from __future__ import annotations

import gc
import time
from dataclasses import dataclass, field

import rclpy
from rclpy.context import Context

from ..device.start_gate import HeldScript
from .contact_detector import ContactDetectorNode
from .executor import make_executor, settle_and_start
from .falcon_driver import FalconDriver
from .force_server import ForceServer
from .session import Readiness
from .sigint import SigintStop
from .visualizer import Visualizer


@dataclass
class Graph:
    context: object
    executor: object
    driver: object
    contact: object
    force: object
    visualizer: object | None = None
    extra: list = field(default_factory=list)

    @property
    def nodes(self):
        return [n for n in (self.driver, self.contact, self.force, self.visualizer, *self.extra)
                if n is not None]

    def wait_ready(self, timeout: float = 300.0) -> float | None:
        """Spin until the driver has seen a force command (the graph carries pose -> contact ->
        force end to end; the palpation script starts then); seconds waited, None on timeout."""
        t0 = time.monotonic()
        if self.spin_for(timeout, until=lambda: self.driver.first_command is not None):
            return time.monotonic() - t0
        return None

    def spin_for(self, seconds: float, until=None) -> bool:
        """Spin for ``seconds`` or until ``until()`` is true (checked between callbacks). Ctrl-C
        raises KeyboardInterrupt here, between callbacks, not inside one (nodes/sigint.py)."""
        if until is not None and until():
            return True
        end = time.monotonic() + seconds
        with SigintStop(spinning=True) as stop:
            while time.monotonic() < end:
                self.executor.spin_once(timeout_sec=0.01)
                if stop.requested:
                    raise KeyboardInterrupt
                if until is not None and until():
                    return True
        return False

    def set_hand(self, script) -> None:
        """The simulated Falcon's hand plays ``script`` (an object with the palpation script's
        interface, e.g. :class:`~haptic_anfis.exam.trainee.TraineeController`) from now on.

        A hand still held at its start (the driver's start gate: until the force source answers
        and the driver's ``release_gate`` opens, e.g. until a side examiner or recorder has
        subscribed) keeps that gate: ``script`` starts when the gate opens, from its own t = 0."""
        held = self.driver.device.script
        if isinstance(held, HeldScript) and held.held:
            held.script = script
            self.driver.device.script = held
        else:
            self.driver.device.script = script

    def summary(self) -> dict:
        s = {'loop': self.driver.summary(), 'contact': self.contact.summary(),
             'force': self.force.summary()}
        if self.visualizer is not None:
            s['visualizer'] = {'marker_arrays': self.visualizer.n_published,
                               'frames_not_drawn': self.visualizer.frames_unwatched}
        return s

    def shutdown(self) -> None:
        """Stop the servo thread first (device to zero force), then the nodes and the context."""
        self.driver.close()
        gc.unfreeze()
        self.executor.shutdown(timeout_sec=1.0)
        for n in self.nodes:
            n.destroy_node()
        rclpy.try_shutdown(context=self.context)


def build_graph(args: list[str] | None = None, visualizer: bool = True,
                overrides: dict[str, list] | None = None, extra=()) -> Graph:
    """Init a fresh rclpy context with ``args`` (e.g. ``['--ros-args', '--params-file', f]``) and
    build the nodes. ``overrides``: {node name: [rclpy.parameter.Parameter, ...]}. ``extra``:
    factories ``f(context) -> Node`` (e.g. a recorder) built before the driver starts publishing;
    they end up in ``Graph.extra``.

    Raises:
        ParameterError / ValueError: a node rejected its parameters (nothing is left running).
    """
    ctx = Context()
    rclpy.init(args=args, context=ctx)
    ov = overrides or {}
    made = []
    try:
        # Consumers first so that the driver's first poses find them.
        force = ForceServer(context=ctx, parameter_overrides=ov.get('force_server', []))
        made.append(force)
        contact = ContactDetectorNode(context=ctx, parameter_overrides=ov.get('contact_detector', []))
        made.append(contact)
        vis = None
        if visualizer:
            vis = Visualizer(context=ctx, parameter_overrides=ov.get('visualizer', []))
            made.append(vis)
        extra_nodes = []
        for factory in extra:
            extra_nodes.append(factory(ctx))
            made.append(extra_nodes[-1])
        driver = FalconDriver(context=ctx, parameter_overrides=ov.get('falcon_driver', []))
        made.append(driver)
        ex = make_executor(ctx)
        for n in made:
            n.readiness = Readiness(n)
            ex.add_node(n)
        settle_and_start(made)
    except BaseException:
        for n in made:
            if hasattr(n, 'servo'):
                n.close()
            n.destroy_node()
        rclpy.try_shutdown(context=ctx)
        raise
    return Graph(ctx, ex, driver, contact, force, vis, extra=extra_nodes)

