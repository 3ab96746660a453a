"""The node helpers, by job: :mod:`.parameters` (declarations, checks, parameter files),
:mod:`.runtime` (loop QoS, stamps, ``run_node``), :mod:`.executor` (the executor factory) and
:mod:`haptic_anfis.resources` (files shipped in ``config/`` and ``data/``). This module only
re-exports them for the node modules that import from here."""
from __future__ import annotations

from ..resources import config_file
from .executor import make_executor, settle_gc
from .parameters import (Param, ParameterError, declare_parameters, finite_vector, non_negative,
                         one_of, positive, resolve_parameters)
from .runtime import LOOP_QOS, interrupted, message_class, run_node, set_stamp, stamp_ns

__all__ = ['config_file', 'make_executor', 'settle_gc', 'Param', 'ParameterError',
           'declare_parameters', 'finite_vector', 'non_negative', 'one_of', 'positive',
           'resolve_parameters', 'LOOP_QOS', 'interrupted', 'message_class', 'run_node',
           'set_stamp', 'stamp_ns']
