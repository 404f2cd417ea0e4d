"""Traces: the logged signals of a run, one row per control period, as a CSV table."""

from __future__ import annotations

from pathlib import Path

import numpy as np


class Traces:
    """Named columns of equal length. ``t`` is the first column [s]."""

    def __init__(self, columns: dict[str, np.ndarray]):
        lengths = {len(v) for v in columns.values()}
        if len(lengths) != 1:
            raise ValueError(f"trace columns differ in length: {sorted(lengths)}")
        self.names = list(columns)
        self.data = np.column_stack([np.asarray(v, dtype=float) for v in columns.values()])

    @property
    def task_axes(self) -> list[str]:
        """The task axes the traces hold (each has a column and its reference ``<axis>_d``)."""
        return [a for a in ("x", "y", "z") if a in self.names and f"{a}_d" in self.names]

    def __getitem__(self, name: str) -> np.ndarray:
        try:
            return self.data[:, self.names.index(name)]
        except ValueError:
            raise KeyError(f"no trace column '{name}'") from None

    def __contains__(self, name: str) -> bool:
        return name in self.names

    def __len__(self) -> int:
        return self.data.shape[0]

    def block(self, prefix: str) -> np.ndarray:
        """Columns prefix1, prefix2, … as a (rows, k) array."""
        k = 1
        cols = []
        while f"{prefix}{k}" in self.names:
            cols.append(self[f"{prefix}{k}"])
            k += 1
        if not cols:
            raise KeyError(f"no trace columns '{prefix}1', '{prefix}2', …")
        return np.column_stack(cols)

    def write_csv(self, path: Path) -> None:
        """Header row, then rows written with 17 significant digits (lossless, deterministic)."""
        np.savetxt(path, self.data, delimiter=",", header=",".join(self.names), comments="", fmt="%.17g")

    @classmethod
    def read_csv(cls, path: Path) -> Traces:
        path = Path(path)
        with path.open() as f:
            header = f.readline().strip().split(",")
            rows = f.read()
        # a run stopped before its first logged row wrote the header alone: zero rows
        data = (
            np.loadtxt(rows.splitlines(), delimiter=",", ndmin=2)
            if rows.strip()
            else np.empty((0, len(header)))
        )
        return cls({name: data[:, i] for i, name in enumerate(header)})
