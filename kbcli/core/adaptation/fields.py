"""Typed fields shared by the adapter's options and its parts' options (bounds a user can type).

A count is bounded by the cost a run would pay at every touch; a blur by a key's width.
"""

from __future__ import annotations

from typing import Annotated

from pydantic import AfterValidator, Field, Strict

#: Upper bounds of the counts a user can type (a cost the run would pay at every touch).
MAX_CANDIDATES = 100_000
MAX_HYPOTHESES = 1_000_000
MAX_KDE_SAMPLES = 1_000_000
#: Largest blur (px) any blur option accepts: a key's width. A map blurred further says nothing,
#: and its Gaussian kernel would outgrow memory (a 1000 px blur asked for 35 GiB).
MAX_BLUR = 50.0


def _blur(v: float) -> float:
    if v > MAX_BLUR:
        raise ValueError(f"must be a blur in [0, {MAX_BLUR:g}] px (<= {MAX_BLUR:g}: a key's width), "
                         f"got {v!r}")
    return v


def choice(*names: str) -> AfterValidator:
    """A field validator: the value must be one of ``names``."""
    def check(v: str) -> str:
        if v not in names:
            raise ValueError(f"must be one of {', '.join(names)}, got {v!r}")
        return v
    return AfterValidator(check)


#: A blur, px: a finite number in [0, MAX_BLUR].
Blur = Annotated[float, Strict(), Field(ge=0, allow_inf_nan=False), AfterValidator(_blur)]
#: A probability in (0, 1].
Fraction = Annotated[float, Strict(), Field(gt=0, le=1, allow_inf_nan=False)]
#: A mixing weight in [0, 1).
Floor = Annotated[float, Strict(), Field(ge=0, lt=1, allow_inf_nan=False)]
