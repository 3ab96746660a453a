"""ament_python package set-up for haptic_anfis.

`colcon build` (and `ros2 run haptic_anfis <node>` on a ROS install) uses the console scripts
installed into ``lib/haptic_anfis`` (see setup.cfg). ``make venv`` installs the same package into a
virtualenv together with ROS 2 Jazzy from PyPI wheels (the ``ros`` extra).
"""
from glob import glob

from setuptools import find_packages, setup

PACKAGE = 'haptic_anfis'

# ROS 2 nodes: executable name -> module:function. Each is also ``ros2 run haptic_anfis <name>``.
NODES: dict[str, str] = {
    'falcon_driver': 'haptic_anfis.nodes.falcon_driver:main',
    'contact_detector': 'haptic_anfis.nodes.contact_detector:main',
    'force_server': 'haptic_anfis.nodes.force_server:main',
    'trainer': 'haptic_anfis.nodes.trainer:main',
    'visualizer': 'haptic_anfis.nodes.visualizer:main',
    'recorder': 'haptic_anfis.nodes.recorder:main',
    'player': 'haptic_anfis.nodes.player:main',
    'examiner': 'haptic_anfis.nodes.examiner:main',
    'web_view': 'haptic_anfis.nodes.web_view:main',
}

setup(
    name=PACKAGE,
    version='0.1.0',
    packages=find_packages(exclude=['test', 'test.*']),
    package_data={PACKAGE: ['py.typed',  # PEP 561: the package's type hints are for its users
                            'data/*.csv', 'data/*.json', 'data/*.stl',
                            'data/*.npz',  # the default case's FE surface displacement (dent)
                            # Fast DDS over UDP only (haptic_anfis.nodes.middleware)
                            'data/dds/*.xml',
                            # the case library (haptic-anfis cases list)
                            'data/cases/*.stl', 'data/cases/*/*.csv', 'data/cases/*/*.json',
                            'data/cases/*/*.npz']},
    data_files=[
        ('share/ament_index/resource_index/packages', [f'resource/{PACKAGE}']),
        (f'share/{PACKAGE}', ['package.xml']),
        (f'share/{PACKAGE}/config', glob('config/*.yaml')),
        (f'share/{PACKAGE}/config/scenes', glob('config/scenes/*.yaml')),
        (f'share/{PACKAGE}/config/trainees', glob('config/trainees/*.yaml')),
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
        # trimesh decodes text formats (ASCII STL with a non-UTF-8 name, or random bytes) with it;
        # without it those fail with "No module named 'charset_normalizer'"
        'charset-normalizer>=3',
        'rosbags>=0.11,<0.12',
        'mcap>=1.2',  # bag recover: stream-reads the MCAP a killed recording left (no summary)
        # the servo threads ask RealtimeKit for real-time priority over D-Bus when SCHED_FIFO is
        # refused (realtime/rtkit.py): pure Python, no C library
        'jeepney>=0.8',
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
        # Intel MKL PARDISO: when importable, the FE's linear solver (an exact LDL^T per Newton
        # iteration, haptic_anfis.tissue.linsolve.PardisoLDLSolver) instead of SciPy's SuperLU
        # with its reused factor; the per-point CPU time before / after is on
        # docs/measurements/fe_point.md. ~1 GB installed, x86-64 only (the marker keeps other
        # machines installable: they fall back to SuperLU). `make venv` installs it.
        'fe-fast': [
            'pypardiso>=0.4; platform_machine == "x86_64"',
        ],
        # `haptic-anfis cases generate --dask`: the FE points on a dask.distributed cluster.
        'dask': [
            'distributed>=2024.1',
        ],
        # The trainee's screen in a browser (haptic-anfis view, --view, the web_view node): a
        # Python server with a bundled three.js client (haptic_anfis.view).
        'view': [
            'viser==1.1.1',
        ],
        'fe': [
            'felupe==11.3.0',
            'threadpoolctl>=3',  # one math thread per FE worker (haptic_anfis.tissue.pointsweep)
            'tqdm>=4',  # the sweeps' progress bar (a plain status line without it)
            'matplotlib>=3.7',  # `haptic-anfis dataset --report` plots
        ],
        # A real Novint Falcon (falcon_driver backend 'falcon'): pure-Python FTDI access over
        # pyusb/libusb. Imported only when that backend is chosen.
        'falcon': [
            'pyftdi>=0.55',
        ],
        # The speed-against-error report (haptic-anfis report, make bench): figures and the
        # scikit-learn peers. scipy's RBFInterpolator comes with scipy already.
        'report': [
            'matplotlib>=3.8',
            'scikit-learn>=1.4',
        ],
        # The xanfis peer of the report. NOT installable beside the rest: xanfis 1.1.0 (and mealpy,
        # which it needs) pin numpy<=1.26.0 while this project runs on numpy 2, so `make venv` puts it
        # in its own virtualenv (.venv-xanfis, with the CPU build of torch) and the report talks to
        # it through a worker process. Listed here so the pins live in one place with the others.
        'xanfis': [
            'torch==2.13.0',
            'xanfis==1.1.0',
        ],
        # The documentation site (make docs: mkdocs build --strict; nothing fetched at build time).
        'docs': [
            'mkdocs==1.6.1',
            'mkdocs-material==9.8.1',
            'mkdocstrings==1.0.8',
            'mkdocstrings-python==2.0.11',
        ],
        'test': [
            'pytest>=8',
            # test_wheel_resources builds the package's wheel offline (--no-build-isolation):
            # bdist_wheel for the setuptools in this environment
            'wheel==0.44.0',
            'pytest-timeout>=2.3',
            'hypothesis>=6.100',
            'colcon-common-extensions==0.3.0',
            'mcap>=1.2',
            'mcap-ros2-support>=0.5',
            'rtree>=1.2',  # trimesh.proximity, the reference the contact benchmark compares against
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
