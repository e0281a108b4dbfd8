"""What the capture readers (_read_*.py) share: a file's first bytes, and rows of numbers read
from text."""

from __future__ import annotations

import io
import warnings
from pathlib import Path

import numpy as np

from ._errors import CaptureError


def file_head(path: Path, n: int) -> bytes:
    """The first n bytes of a file (without reading a large capture whole)."""
    with open(path, "rb") as f:
        return f.read(n)


def read_rows(path: Path, f, rows: int, what: str, usecols=None) -> np.ndarray:
    """Up to `rows` whitespace-separated rows of numbers from a binary file object, as (R, C)
    float64; CaptureError for a row that is not numbers or has another number of them."""
    try:
        with warnings.catch_warnings():  # an empty input warns; the caller counts the rows
            warnings.simplefilter("ignore", UserWarning)
            out = np.loadtxt(
                io.TextIOWrapper(f, encoding="ascii"),
                dtype=np.float64,
                ndmin=2,
                max_rows=rows,
                comments=None,
                usecols=usecols,
            )
    except UnicodeDecodeError:
        raise CaptureError(f"{path}: the {what} holds non-text bytes") from None
    except ValueError as exc:
        raise CaptureError(f"{path}: bad {what}: {str(exc)[:200]}") from None
    return out
