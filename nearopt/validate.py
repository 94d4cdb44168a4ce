"""Argument checks every layer shares (the request, the command line, batches, sampling,
verification), one message each."""

from __future__ import annotations

import numpy as np

from .errors import ConfigurationError

__all__ = ["MAX_RATE", "MAX_SAMPLES", "check_rate", "check_samples", "is_number", "real_array"]

MAX_RATE = 1e6
"""[Hz] A sampling or controller rate above a megahertz is a mistake, not a controller."""
MAX_SAMPLES = 10_000_000
"""Samples of a written motion (rate × t_e) at most: beyond, a file would take gigabytes."""


def real_array(value: object) -> np.ndarray | None:
    """``value`` as an array of floats if it holds real numbers only (ints or floats: not
    strings, bools or complex numbers, which ``float()`` would read or half-read), else None."""
    if isinstance(value, str | bytes):
        return None
    try:
        items = np.asarray(value, dtype=object).ravel()  # each element's own type
        array = np.asarray(value)
    except (TypeError, ValueError):
        return None
    if array.dtype.kind not in "iuf" or any(isinstance(x, bool | np.bool_) for x in items):
        return None  # (NumPy reads [True, 0] as integers)
    return array.astype(float)


def is_number(value: object) -> bool:
    """Whether ``value`` is a real number: Python's int or float or NumPy's integer or floating
    scalar (not a bool, which Python counts as an int; maybe not finite)."""
    return isinstance(value, int | float | np.integer | np.floating) and not isinstance(value, bool)


def check_rate(rate: object, what: str = "rate") -> float:
    """A sampling or controller rate [Hz]: a finite number in (0, :data:`MAX_RATE`].

    Raises
    ------
    ConfigurationError
        ``"{what} must be a number of Hz in (0, 1e+06], got …"``.
    """
    if not (is_number(rate) and np.isfinite(rate) and 0 < rate <= MAX_RATE):  # type: ignore[operator]
        raise ConfigurationError(
            f"{what} must be a number of Hz in (0, {MAX_RATE:.0e}], got {rate!r}"
        )
    return float(rate)  # type: ignore[arg-type]


def check_samples(rate: float, duration: float, what: str = "rate", at_least: bool = False) -> None:
    """That a motion of ``duration`` [s] written at ``rate`` [Hz] has at most
    :data:`MAX_SAMPLES` samples. ``what`` names the rate in the message; ``at_least`` says the
    duration is a lower bound (a motion not planned yet: "would last at least").

    Raises
    ------
    ConfigurationError
        Naming the rate, the duration and the cap.
    """
    if rate * duration > MAX_SAMPLES:
        days = f" ({duration / 86400:.3g} days)" if duration > 86400 else ""
        lasts = "would last at least" if at_least else "lasts"
        raise ConfigurationError(
            f"the motion {lasts} {duration:.4g} s{days}: {what} {rate:g} Hz over it gives more "
            f"than {MAX_SAMPLES:.0e} samples to check; ask for a lower rate, or raise the limits "
            "that make it this slow"
        )
