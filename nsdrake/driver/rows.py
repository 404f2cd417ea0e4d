"""Signals recorded once a period into preallocated rows (no allocation per period), read
back as logs shaped as Drake's ``VectorLog`` (``sample_times()``, ``data()``), which
:func:`nsdrake.experiment.simulate.collect_traces` reads: the drive's controller side
(:class:`nsdrake.driver.controller_side.Recorder`) and the simulated driver's ground truth
(:class:`nsdrake.driver.simulated_driver.SimulatedDriver`) both keep their records so."""

from __future__ import annotations

import numpy as np


class Log:
    """A logger's record made of arrays (``sample_times()``, ``data()``)."""

    def __init__(self, times: np.ndarray, data: np.ndarray):
        self._times, self._data = times, data

    def sample_times(self) -> np.ndarray:
        return self._times

    def data(self) -> np.ndarray:
        return self._data


class Rows:
    """One row per period: the time in column 0, then each signal of ``sizes`` ({name:
    size}) in its ``slices[name]``; ``capacity`` rows preallocated, doubled when a run
    outlasts them (rare)."""

    def __init__(self, sizes: dict[str, int], capacity: int):
        self.slices, start = {}, 1
        for name, size in sizes.items():
            self.slices[name] = slice(start, start + size)
            start += size
        self.rows = np.zeros((max(1, capacity), start))
        self.count = 0

    def next_row(self) -> np.ndarray:
        """The row the next period fills (it counts once :meth:`done` is called)."""
        if self.count == self.rows.shape[0]:  # longer than planned: grow (rare)
            self.rows = np.concatenate([self.rows, np.zeros_like(self.rows)])
        return self.rows[self.count]

    def done(self) -> None:
        """The row :meth:`next_row` gave is complete: it belongs to the record."""
        self.count += 1

    def add(self, t: float, values: dict) -> None:
        """One row: the time ``t`` and each signal's value, by name."""
        row = self.next_row()
        row[0] = t
        for name, value in values.items():
            row[self.slices[name]] = value
        self.done()

    def logs(self) -> dict[str, Log]:
        """{name: Log} of every signal, the rows recorded so far."""
        rows = self.rows[: self.count]
        return {name: Log(rows[:, 0], rows[:, part].T) for name, part in self.slices.items()}
