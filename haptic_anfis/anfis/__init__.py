"""ANFIS force models: first-order Takagi–Sugeno, triangular MFs on a grid partition, hybrid learning.

Pure Python (numpy, numba); nothing here imports ROS.

- :class:`ForceModel` — the three-output (Fx, Fy, Fz) model the force server uses.
- :class:`SugenoModel` — one output; :func:`train` its hybrid learning; :func:`search_structure`.
"""
from .force_model import ForceModel, rmse, train_on_dataset
from .model_file import FORMAT_VERSION, ModelFileError
from .structure import search_structure
from .sugeno import SugenoModel
from .training import solve_consequents, train

__all__ = ['ForceModel', 'SugenoModel', 'ModelFileError', 'FORMAT_VERSION', 'rmse',
           'search_structure', 'solve_consequents', 'train', 'train_on_dataset']
