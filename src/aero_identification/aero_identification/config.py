"""Hyperparameters of the identification pipeline (pipeline.py), in a module of their own so
that the identifier node can hold them without loading the numerical stack."""

from dataclasses import dataclass


@dataclass(frozen=True)
class IdentificationConfig:
    """Hyperparameters of the pipeline (the identifier node's parameters)."""

    nx: int = 1  # states of BLA SS and PNLSS (paper: 1)
    degrees: tuple[int, ...] = (2, 3, 4, 5)  # PNLSS monomial degrees (paper: 2..5)
    structure: str = "full"
    max_iter: int = 100  # LM iterations (the paper used 50 for its order scan)
    estimation_realization: int = 0
    validation_realization: int = 1
    min_periods: int = 2
