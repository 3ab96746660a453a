"""haptic_anfis: real-time ANFIS soft-tissue force rendering for a breast-palpation haptic simulator.

The core sub-packages (:mod:`haptic_anfis.anfis`, :mod:`haptic_anfis.dataset`, and later
``contact``, ``tissue``, ``device``) are plain Python and import nothing from ROS. SI units inside:
metres, newtons, seconds.
"""
__version__ = '0.1.0'
