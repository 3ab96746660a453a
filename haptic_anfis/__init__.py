"""haptic_anfis: real-time ANFIS soft-tissue force rendering for a breast-palpation haptic simulator.

The core sub-packages (:mod:`haptic_anfis.anfis`, :mod:`haptic_anfis.tissue.dataset`, and later
``contact``, ``tissue``, ``device``) are plain Python and import nothing from ROS. SI units inside:
metres, newtons, seconds.
"""
import os as _os

# One BLAS/OpenMP thread unless the user says otherwise. Measured here: on a loaded 2-core machine
# OpenBLAS's thread pool made a 470x120 SVD take 1.3 s instead of 7 ms, and a real-time loop must
# not compete with spinning BLAS threads. Takes effect only if numpy is not imported yet.
for _var in ('OPENBLAS_NUM_THREADS', 'OMP_NUM_THREADS', 'MKL_NUM_THREADS'):
    _os.environ.setdefault(_var, '1')

# numba's kernel cache: beside the sources, or the user cache directory when the package
# directory is not writable (see numba_cache.py). Before anything imports numba.
from .numba_cache import configure as _configure_numba_cache  # noqa: E402

_configure_numba_cache()

from ._version import __version__  # noqa: E402

__all__ = ['__version__']
