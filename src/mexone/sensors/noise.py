"""Gazebo's sensor noise: gaussian with a bias drawn once per run, optionally quantized.

As Gazebo's GaussianNoiseModel: output = input + N(mean, stddev) + bias, where the bias is drawn
from N(bias_mean, bias_stddev) when the sensor starts and flips sign with probability one half.
Each sensor has its own generator, seeded from its name, so runs are reproducible.
"""

from __future__ import annotations

import zlib

import numpy as np

from mexone.description.sensors import Noise

__all__ = ["NoiseModel"]


class NoiseModel:
    def __init__(self, channels: list[Noise], seed_name: str, seed: int = 0):
        self.rng = np.random.default_rng([zlib.crc32(seed_name.encode()), seed])
        self.mean = np.array([n.mean for n in channels], dtype=float)
        self.stddev = np.array([n.stddev for n in channels], dtype=float)
        self.precision = np.array([n.precision if n.type == "gaussian_quantized" else 0.0
                                   for n in channels])
        bias = self.rng.normal([n.bias_mean for n in channels],
                               [n.bias_stddev for n in channels])
        self.bias = bias * self.rng.choice([-1.0, 1.0], size=len(channels))
        self.active = bool(any(n.active for n in channels))

    @property
    def variance(self) -> np.ndarray:
        return self.stddev**2

    def apply(self, values: np.ndarray) -> np.ndarray:
        if not self.active:
            return values
        out = values + self.mean + self.bias + self.rng.normal(0.0, 1.0, len(values)) * self.stddev
        quantized = self.precision > 0
        if quantized.any():
            out[quantized] = np.round(out[quantized] / self.precision[quantized]) \
                * self.precision[quantized]
        return out
