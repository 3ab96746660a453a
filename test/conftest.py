"""Shared fixtures, and the test rooms. Tests are seeded and isolated: ROS tests use their own
domain, localhost only.

A test file's folder under ``test/`` is its room and its marker (docs/tests.md): ``unit/`` (the
ROS-free core, seconds), ``ros/`` (a ROS graph: rclpy, node processes), ``browser/`` (a headless
chromium on the view's page; slow too), ``slow/`` (a file whose tests together take more than
~10 s). Moving a file between folders is all it takes to change its room. Helpers and fixture
files live in ``support/`` (on ``sys.path``: ``from falcon_fake import FakeFalcon``), data in
``support/data/``.
"""
from __future__ import annotations

import os
import sys
import tempfile
from pathlib import Path

import haptic_anfis  # noqa: F401  (first: it pins BLAS to one thread before numpy loads)
import numpy as np
import pytest
from hypothesis import settings

# Isolation for any test that touches ROS 2 (set before rclpy is imported anywhere): ALWAYS a
# domain of the test run's own, never an inherited ROS_DOMAIN_ID (a user's session on that domain
# and the tests corrupted each other: issue 27.5), and discovery on this machine only. The id
# comes from the pid, in 40-89 (the cross-process tests take theirs in 60-119 and 120-199); a
# session started by a test refuses a domain where another session's driver already runs.
TEST_DOMAIN_ID = 40 + os.getpid() % 50
os.environ['ROS_DOMAIN_ID'] = str(TEST_DOMAIN_ID)
os.environ['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'
os.environ.pop('ROS_STATIC_PEERS', None)  # no discovery of peers outside this machine

# Nor a user's own data: their case folder, trainee record and XDG data home (a case of
# theirs would join the library every test lists) are replaced by an empty folder of the run's.
for _name in ('HAPTIC_ANFIS_CASE_DIR', 'HAPTIC_ANFIS_DB'):
    os.environ.pop(_name, None)
os.environ['XDG_DATA_HOME'] = tempfile.mkdtemp(prefix='haptic_anfis_test_data_')

settings.register_profile('ci', derandomize=True, deadline=None, max_examples=60)
settings.load_profile('ci')

TEST_DIR = Path(__file__).resolve().parent
#: the rooms: a folder of test/ and the marker its tests get (registered in setup.cfg)
ROOMS = ('unit', 'ros', 'browser', 'slow')
# the helpers the tests import by name, and the rooms: a test file may reuse another's helpers
# (``from test_nodes_process import launch``) whichever room either is in
for _d in ('support', *ROOMS):
    sys.path.insert(0, str(TEST_DIR / _d))


def pytest_collection_modifyitems(config, items):
    """Mark every test with its file's room (the folder under test/ it is in)."""
    for item in items:
        try:
            room = Path(str(item.path)).resolve().relative_to(TEST_DIR).parts[0]
        except ValueError:  # a test outside test/ (a path given on the command line)
            continue
        if room in ROOMS:
            item.add_marker(getattr(pytest.mark, room))
        if room == 'browser':  # a chromium starts and loads the page: a slow test too
            item.add_marker(pytest.mark.slow)


@pytest.fixture(autouse=True)
def _no_case_dir_left_behind():
    """``--case-dir`` run in the test process sets ``HAPTIC_ANFIS_CASE_DIR`` for the nodes it
    starts; the next test must not inherit it."""
    yield
    os.environ.pop('HAPTIC_ANFIS_CASE_DIR', None)


@pytest.fixture(scope='session')
def synthetic():
    from haptic_anfis.tissue.synthetic import make_synthetic_dataset
    return make_synthetic_dataset(seed=0)


@pytest.fixture(scope='session')
def small_model(synthetic):
    """A plain-form ForceModel with a fixed 3-2-2-2 / 3-3-3-2 / 2-2-2-2 structure (fast to train)."""
    from haptic_anfis.anfis import ForceModel
    return ForceModel(structure=[(3, 2, 2, 2), (3, 3, 3, 2), (2, 2, 2, 2)], epochs=15,
                      form='plain').fit(synthetic.X, synthetic.Y, groups=synthetic.point)


@pytest.fixture
def ctx():
    """An rclpy context of the test's own (on the test run's domain), shut down after it."""
    rclpy = pytest.importorskip('rclpy')
    from rclpy.context import Context
    c = Context()
    rclpy.init(context=c)
    yield c
    rclpy.try_shutdown(context=c)


@pytest.fixture
def rng():
    return np.random.default_rng(1234)
