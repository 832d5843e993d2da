"""Checks shared by the identifiers."""

from __future__ import annotations

from ..errors import DataError
from .data import Samples


def require_samples(samples: Samples, n_usable: int, n_needed: int, method: str) -> None:
    """Raise :class:`DataError` when there are fewer usable samples than the fit needs."""
    if n_usable < n_needed:
        raise DataError(
            f"{samples.source}: {method} needs at least {n_needed} usable samples for this "
            f"model, got {n_usable}"
        )
