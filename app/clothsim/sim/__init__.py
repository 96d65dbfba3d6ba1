"""Simulation state and the Numba kernels that advance it."""

from .simulation import Simulation

__all__ = ["Simulation"]
