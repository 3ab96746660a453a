"""What the report measures against: the haptic loop's budget and the paper's figures."""
from __future__ import annotations

__all__ = ['HAPTIC_BUDGET_US', 'PAPER_RMSE_N', 'PAPER_EVALS_PER_S']

HAPTIC_BUDGET_US = 1000.0               # one servo tick at 1 kHz
PAPER_RMSE_N = (0.0791, 0.0063, 0.0181)  # Amirkhani & Nahvi, test RMSE Fx, Fy, Fz on their FE data
PAPER_EVALS_PER_S = 1e5
