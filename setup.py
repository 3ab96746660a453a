"""ament_python package set-up for haptic_anfis.

`colcon build` (and `ros2 run haptic_anfis <node>` on a ROS install) uses the console scripts
installed into ``lib/haptic_anfis`` (see setup.cfg). ``make venv`` installs the same package into a
virtualenv together with ROS 2 Jazzy from PyPI wheels (the ``ros`` extra).
"""
from glob import glob

from setuptools import find_packages, setup

PACKAGE = 'haptic_anfis'

# ROS 2 nodes: executable name -> module:function. Each is also ``ros2 run haptic_anfis <name>``.
NODES: dict[str, str] = {}

setup(
    name=PACKAGE,
    version='0.1.0',
    packages=find_packages(exclude=['test', 'test.*']),
    package_data={PACKAGE: ['data/*.csv', 'data/*.json', 'data/*.stl']},
    data_files=[
        ('share/ament_index/resource_index/packages', [f'resource/{PACKAGE}']),
        (f'share/{PACKAGE}', ['package.xml']),
        (f'share/{PACKAGE}/config', glob('config/*.yaml')),
        (f'share/{PACKAGE}/config/scenes', glob('config/scenes/*.yaml')),
    ],
    python_requires='>=3.10',
    # Plain-Python dependencies. rclpy and the message packages come from the ROS install (or the
    # `ros` extra below, PyPI wheels of ROS 2 Jazzy for CPython 3.11).
    install_requires=[
        'setuptools',
        'numpy>=1.24',
        'scipy>=1.10',
        'numba>=0.58',
        'pyyaml>=6',
        'trimesh>=4',
        'rosbags>=0.11,<0.12',
    ],
    extras_require={
        'ros': [
            'ros-jazzy-rclpy==7.1.6',
            'ros-jazzy-common-interfaces==5.3.6',
            'ros-jazzy-rmw-fastrtps-cpp==8.4.3',
            'ros-jazzy-std-srvs==5.3.6',
            'ros-jazzy-visualization-msgs==5.3.6',
        ],
        # Finite-element data generation (haptic_anfis.tissue). Optional for running the simulator.
        'fe': [
            'felupe==11.3.0',
            'matplotlib>=3.7',  # `haptic-anfis dataset --report` plots
        ],
        'test': [
            'pytest>=8',
            'pytest-timeout>=2.3',
            'hypothesis>=6.100',
            'colcon-common-extensions==0.3.0',
            'mcap>=1.2',
            'mcap-ros2-support>=0.5',
        ],
    },
    zip_safe=True,
    maintainer='haptic_anfis developers',
    maintainer_email='haptic-anfis@example.org',
    description='Real-time ANFIS soft-tissue force rendering for a breast-palpation haptic simulator.',
    license='Apache-2.0',
    entry_points={
        'console_scripts': [
            'haptic-anfis = haptic_anfis.cli:main',
            *(f'{name} = {target}' for name, target in NODES.items()),
        ],
    },
)
