"""Ctrl-C ends a spinning graph between callbacks, never inside one (nodes/sigint.py): raised
inside a force-model evaluation, numba turned it into a SystemError and ``sim`` ended in a
traceback (CI, test_graph_priority's Ctrl-C test)."""
from __future__ import annotations

import os
import signal

import pytest
import rclpy
from rclpy.context import Context
from rclpy.executors import SingleThreadedExecutor

from haptic_anfis.nodes.graph import Graph
from haptic_anfis.nodes.sigint import SigintStop


def test_ctrl_c_inside_a_callback_ends_spin_for_after_that_callback():
    ctx = Context()
    rclpy.init(context=ctx)
    node = rclpy.create_node('sigint_probe', context=ctx)
    ex = SingleThreadedExecutor(context=ctx)
    ex.add_node(node)
    done = []

    def callback():
        os.kill(os.getpid(), signal.SIGINT)
        total = sum(range(10_000))  # bytecodes after the signal: Python would raise here
        done.append(total)

    node.create_timer(0.01, callback)
    before = signal.getsignal(signal.SIGINT)
    try:
        with pytest.raises(KeyboardInterrupt):
            Graph(ctx, ex, None, None, None).spin_for(10.0)
    finally:
        ex.shutdown()
        node.destroy_node()
        rclpy.try_shutdown(context=ctx)
    assert done == [sum(range(10_000))]  # the callback ran to its end, once
    assert signal.getsignal(signal.SIGINT) is before  # the handler is put back


def test_not_spinning_it_raises_at_once_and_restores_the_handler():
    before = signal.getsignal(signal.SIGINT)
    with SigintStop() as stop:
        with pytest.raises(KeyboardInterrupt):
            os.kill(os.getpid(), signal.SIGINT)
            sum(range(10_000))
        stop.spinning = True
        os.kill(os.getpid(), signal.SIGINT)
        sum(range(10_000))
        assert stop.requested
    assert signal.getsignal(signal.SIGINT) is before
