"""The palpation case library (no ROS imports).

- :mod:`.library`: what a case is (scene + dataset + mesh + model), lookup with clear errors,
  random draw by seed, :func:`resolve_case` for the nodes' ``case`` parameters.
- :mod:`.generate`: FE sweep -> dataset, surface mesh, trained model (resumable, any executor).
- :mod:`.summary`: the listing's figures, including each lesion's FE-vs-model contrast.
"""
from .library import (CASE_DIR_ENV, DEFAULT_CASE, Case, CaseError, CaseLibrary, get_case, library,
                      random_case, resolve_case, use_case_dir, user_case_dir)

__all__ = ['CASE_DIR_ENV', 'DEFAULT_CASE', 'Case', 'CaseError', 'CaseLibrary', 'get_case',
           'library', 'random_case', 'resolve_case', 'use_case_dir', 'user_case_dir']
