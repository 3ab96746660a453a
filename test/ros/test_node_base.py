"""A node whose constructor fails leaves nothing on the ROS graph (nodes/base.py): before, its
name stayed there until the garbage collector freed it, even with its context shut down, and a
session started later in the same process (a test, ``sim``'s graph) refused the domain as
another session's."""
from __future__ import annotations

import gc
import importlib
import inspect

import pytest

rclpy = pytest.importorskip('rclpy')
from rclpy.parameter import Parameter  # noqa: E402

from haptic_anfis.nodes.base import HapticNode  # noqa: E402
from haptic_anfis.realtime.processes import node_names  # noqa: E402


def node_class(name: str) -> type:
    mod = importlib.import_module(f'haptic_anfis.nodes.{name}')
    found = [c for c in vars(mod).values() if inspect.isclass(c) and issubclass(c, HapticNode)
             and c is not HapticNode and c.__module__ == mod.__name__]
    assert len(found) == 1, (name, found)
    return found[0]


def test_every_node_of_the_package_is_a_haptic_node():
    for name in node_names():
        assert issubclass(node_class(name), HapticNode)


# Failures that come after rclpy has made the node (the parameter checks come before it)
FAILURES = {
    'contact_detector': ({'mesh_path': '{bad_mesh}'}, 'not a mesh file'),
    'visualizer': ({'mesh_path': '{bad_mesh}'}, 'not a mesh file'),
    'force_server': ({'model_path': '{bad_json}'}, 'not a haptic_anfis force-model file'),
    'examiner': ({'scene': '{bad_json}'}, 'unknown key'),
    'falcon_driver': ({'backend': 'falcon', 'servo_loop': 'native'}, "servo_loop: got 'native'"),
    'web_view': ({'case': 'no_such_case'}, "unknown case 'no_such_case'"),
    'player': ({'bag_path': '{missing}'}, 'bag'),
    'recorder': ({'output': '{unwritable}'}, 'is a file, not a folder'),
}



@pytest.mark.parametrize('name', sorted(FAILURES))
def test_a_node_that_fails_to_build_leaves_the_graph(ctx, tmp_path, name):
    """With the garbage collector off (nothing else would free it) and the error still held
    (its traceback holds the node, as a caller that logs or keeps it does), the constructor's
    error comes out unchanged and the node is already off the graph."""
    bad_mesh = tmp_path / 'bad.stl'
    bad_mesh.write_text('solid nonsense\nfacet normal x y z\n')
    bad_json = tmp_path / 'bad.json'
    bad_json.write_text('{"format": "nope"}')
    where = dict(bad_mesh=bad_mesh, bad_json=bad_json, missing=tmp_path / 'no_bag',
                 unwritable=bad_json / 'bag')  # under a file
    overrides, message = FAILURES[name]
    params = [Parameter(k, value=v.format(**where)) for k, v in overrides.items()]
    probe = rclpy.create_node('graph_probe', context=ctx, start_parameter_services=False)
    gc.disable()
    try:
        with pytest.raises(Exception, match=message) as failed:
            node_class(name)(context=ctx, parameter_overrides=params)
        assert probe.get_node_names() == ['graph_probe'], failed.value
    finally:
        gc.enable()
        probe.destroy_node()
