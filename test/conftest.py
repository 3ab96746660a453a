"""Shared fixtures. Tests are seeded and isolated: ROS tests use their own domain, localhost only."""
from __future__ import annotations

import os

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

settings.register_profile('ci', derandomize=True, deadline=None, max_examples=60)
settings.load_profile('ci')


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
