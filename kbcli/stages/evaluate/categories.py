"""The evaluation's displacement categories (:class:`Category`): fixed displacement
parametrizations grouped by size (:data:`kbcli.stages.perturb.CATEGORIES`), and the paper's
(:func:`_paper_categories`)."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any, ClassVar

import numpy as np
from pydantic import Field, model_validator

from kbcli.core.config import Name, Number, Positive
from kbcli.core.instrument import transforms
from kbcli.errors import ConfigError
from kbcli.stages.config import StageConfig
from kbcli.stages.perturb import CATEGORIES as SIZE_CATEGORIES
from kbcli.stages.perturb import displacement_size


class Category(StageConfig):
    """A group of displacement parametrizations (``(dx, dy)`` or ``(angle, dx, dy)``) of similar
    size: each translation's norm is at most ``limit`` px (for the size categories of
    :data:`kbcli.stages.perturb.CATEGORIES`, also above their lower bound; their ``limit`` is
    their upper bound, the default)."""

    what: ClassVar[str] = "categories"

    name: Name
    limit: Positive | None = None
    displacements: tuple[tuple[Number, ...], ...] = Field(min_length=1)

    @classmethod
    def where(cls, data: Mapping[str, Any]) -> str:
        return f"categories.{data.get('name')}"

    @model_validator(mode="before")
    @classmethod
    def _size_limit(cls, data: Any) -> Any:
        """A size category's limit defaults to its upper bound."""
        if isinstance(data, Mapping) and data.get("limit") is None:
            known = SIZE_CATEGORIES.get(data.get("name"))
            if known is not None:
                data = {**data, "limit": known[1]}
        return data

    @model_validator(mode="after")
    def _check_limit(self) -> Category:
        known = SIZE_CATEGORIES.get(self.name)
        if self.limit is None:
            raise ValueError(f"limit is needed: {self.name!r} is not one of the size categories "
                             f"{', '.join(SIZE_CATEGORIES)}")
        if known is not None and self.limit != known[1]:
            raise ValueError(f"limit is {self.limit:g} px but the size category {self.name} is "
                             f"({known[0]:g}, {known[1]:g}] px (kbcli.stages.perturb.CATEGORIES)")
        return self

    @classmethod
    def from_table(cls, name: str, table: Any) -> Category:
        """A category from its TOML table ``{limit, displacements}``."""
        if not isinstance(table, Mapping):
            raise ConfigError(f"categories.{name} must be a table with displacements")
        extra = sorted(set(table) - {"limit", "displacements"})
        if extra or "displacements" not in table:
            raise ConfigError(f"categories.{name} must have displacements (and may have limit)"
                              + (f" (unknown: {', '.join(extra)})" if extra else ""))
        return cls(name=name, limit=table.get("limit"), displacements=table["displacements"])

    @property
    def lower(self) -> float:
        """Exclusive lower bound of the sizes (px): the size category's, else 0."""
        return SIZE_CATEGORIES.get(self.name, (0.0, self.limit))[0]

    def check_rows(self, family: str) -> None:
        """ConfigError unless every displacement has ``family``'s parameters and a size in
        ``(lower, limit]``."""
        names = transforms.FAMILIES.get(family).params
        for row in self.displacements:
            if len(row) != len(names):
                raise ConfigError(
                    f"categories.{self.name}: a {family} displacement has {len(names)} "
                    f"parameters ({', '.join(names)}), got {list(row)}")
            size = float(displacement_size(np.asarray(row, float)))
            if size > self.limit + 1e-9:
                raise ConfigError(
                    f"categories.{self.name}: displacement {list(row)} is {size:.2f} px, "
                    f"beyond the category's limit of {self.limit:g} px")
            if size <= self.lower:
                raise ConfigError(
                    f"categories.{self.name}: displacement {list(row)} is {size:.2f} px, not "
                    f"above the category's lower bound of {self.lower:g} px (sizes are Euclidean)")

    def to_dict(self) -> dict:
        return {"limit": self.limit, "displacements": [list(r) for r in self.displacements]}


def _paper_categories() -> tuple[Category, ...]:
    return (
        Category(name="small", limit=10.0, displacements=(
            (3.76, 1.37), (-2.05, 5.64), (-7.52, -2.74), (3.42, -9.39))),
        Category(name="medium", limit=20.0, displacements=(
            (5.07, 10.88), (-13.59, 6.34), (-7.61, -16.31), (18.12, -8.45))),
        Category(name="large", limit=40.0, displacements=(
            (19.15, 16.07), (-19.28, 22.98), (-26.81, -22.5), (25.71, -30.64))),
    )
