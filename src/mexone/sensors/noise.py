"""Gazebo's sensor noise: gaussian with a bias drawn once per run, optionally quantized.

As Gazebo's GaussianNoiseModel: output = input + N(mean, stddev) + bias, where the bias is drawn
from N(bias_mean, bias_stddev) when the sensor starts and flips sign with probability one half.
Each sensor has its own generator, seeded from its name, so runs are reproducible. The standard
normal draws come in blocks (one numpy call per BLOCK readings, not one per reading: a reading
at 100 Hz then costs a row lookup).
"""

from __future__ import annotations

import zlib

import numpy as np

from mexone.description.sensors import Noise

__all__ = ["NoiseModel", "BLOCK"]

BLOCK = 256  # readings drawn per numpy call


class NoiseModel:
    def __init__(self, channels: list[Noise], seed_name: str, seed: int = 0) -> None:
        self.rng = np.random.default_rng([zlib.crc32(seed_name.encode()), seed])
        self.mean = np.array([n.mean for n in channels], dtype=float)
        self.stddev = np.array([n.stddev for n in channels], dtype=float)
        self.precision = np.array([n.precision if n.type == "gaussian_quantized" else 0.0
                                   for n in channels])
        bias = self.rng.normal([n.bias_mean for n in channels],
                               [n.bias_stddev for n in channels])
        self.bias = bias * self.rng.choice([-1.0, 1.0], size=len(channels))
        self.active = bool(any(n.active for n in channels))
        self.offset = self.mean + self.bias  # what every reading adds before its draw
        self._draws = np.zeros((0, len(channels)))
        self._rows: list[np.ndarray] = []
        self._row = 0
        self._quantized = bool((self.precision > 0).any())

    @property
    def variance(self) -> np.ndarray:
        return self.stddev**2

    def _next(self) -> np.ndarray:
        """This reading's noise per channel (mean and bias included), from the current block."""
        if self._row >= len(self._draws):
            self._draws = self.rng.normal(0.0, 1.0, (BLOCK, len(self.stddev))) * self.stddev \
                + self.offset
            self._rows = list(self._draws)  # each reading's row as a view, sliced once
            self._row = 0
        self._row += 1
        return self._draws[self._row - 1]

    def add_to(self, values: np.ndarray) -> None:
        """Add this reading's noise to `values` in place (one value per channel)."""
        if self._quantized:
            values[:] = self.apply(values)
            return
        row = self._row  # _next, inlined: this runs for every noisy reading, between steps
        if row >= len(self._draws):
            self._next()
        else:
            self._row = row + 1
        values += self._rows[self._row - 1]

    def apply(self, values: np.ndarray) -> np.ndarray:
        """`values` with this reading's noise (one value per channel, or one channel over many
        values: an image)."""
        if not self.active:
            return values
        if len(values) != len(self.stddev):
            out = values + self.offset + self.rng.normal(0.0, 1.0, len(values)) * self.stddev
        else:
            out = values + self._next()
        if self._quantized:
            quantized = self.precision > 0
            out[quantized] = np.round(out[quantized] / self.precision[quantized]) \
                * self.precision[quantized]
        return out
