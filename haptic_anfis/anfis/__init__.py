"""ANFIS: first-order Takagi–Sugeno models on a grid partition, hybrid learning; the force models.

Pure Python (numpy, numba); nothing here imports ROS.

- :class:`ANFIS` — the general estimator: n inputs, one output, four MF families, hybrid learning.
- :class:`ForceModel` — the three-output (Fx, Fy, Fz) model the force server uses: three
  triangular :class:`ANFIS` estimators, compiled together for the real-time query.
- :class:`SugenoModel` — the pinned triangular partition of model files before format version 3
  (read by the migration; :func:`train` its hybrid learning); :func:`search_structure`.
"""
from .estimator import ANFIS, ANFISInputError
from .force_model import ForceModel, rmse, train_on_dataset
from .model_file import FORMAT_VERSION, ModelFileError
from .structure import search_structure
from .sugeno import SugenoModel
from .training import solve_consequents, train

__all__ = ['ANFIS', 'ANFISInputError', 'ForceModel', 'SugenoModel', 'ModelFileError',
           'FORMAT_VERSION', 'rmse', 'search_structure', 'solve_consequents', 'train',
           'train_on_dataset']
