#!/usr/bin/python3
"""Independent reference for src/models/scheduler.{h,cpp}: Euler ancestral sampling with v-prediction and
classifier-free guidance, written from the formulas (numpy, float64), never by calling the C++ code.

It replays the C++ noise generator from its documented definition (std::mt19937_64 + Box-Muller, see
scheduler.h), implementing MT19937-64 itself (checked against the C++ standard's required 10000th output), runs
a fixed synthetic "model" through the full sampling loop for several configurations, and writes the schedules
and final latents as JSON for src/models/scheduler_test.cpp to compare against.

Usage: scheduler_reference.py OUT.json
"""
import json
import math
import os
import sys

import numpy as np

MASK64 = (1 << 64) - 1


class MT19937_64:
    """MT19937-64 (Matsumoto & Nishimura), the parameters std::mt19937_64 is defined with."""
    N, M = 312, 156
    MATRIX_A = 0xB5026F5AA96619E9
    UPPER, LOWER = 0xFFFFFFFF80000000, 0x7FFFFFFF

    def __init__(self, seed):
        self.mt = [0] * self.N
        self.mt[0] = seed & MASK64
        for i in range(1, self.N):
            prev = self.mt[i - 1]
            self.mt[i] = (6364136223846793005 * (prev ^ (prev >> 62)) + i) & MASK64
        self.index = self.N

    def _twist(self):
        mt = self.mt
        for i in range(self.N):
            x = (mt[i] & self.UPPER) | (mt[(i + 1) % self.N] & self.LOWER)
            xa = x >> 1
            if x & 1:
                xa ^= self.MATRIX_A
            mt[i] = mt[(i + self.M) % self.N] ^ xa
        self.index = 0

    def __call__(self):
        if self.index >= self.N:
            self._twist()
        y = self.mt[self.index]
        self.index += 1
        y ^= (y >> 29) & 0x5555555555555555
        y ^= (y << 17) & 0x71D67FFFEDA60000
        y ^= (y << 37) & 0xFFF7EEE000000000
        y ^= y >> 43
        return y & MASK64


class Gaussian:
    """Box-Muller over MT19937-64 exactly as scheduler.h documents it (values rounded to float32)."""

    def __init__(self, seed):
        self.engine = MT19937_64(seed)
        self.spare = None

    def next(self):
        if self.spare is not None:
            v, self.spare = self.spare, None
            return v
        a, b = self.engine() >> 11, self.engine() >> 11
        u1 = (a + 1) * 2.0 ** -53
        u2 = b * 2.0 ** -53
        r = math.sqrt(-2.0 * math.log(u1))
        self.spare = r * math.sin(2.0 * math.pi * u2)
        return r * math.cos(2.0 * math.pi * u2)

    def draw(self, n):
        return np.array([self.next() for _ in range(n)], dtype=np.float32).astype(np.float64)


def alphas_cumprod(cfg):
    T = cfg["num_train_timesteps"]
    if cfg["beta_schedule"] == "linear":
        betas = np.linspace(cfg["beta_start"], cfg["beta_end"], T, dtype=np.float64)
    else:
        betas = np.linspace(cfg["beta_start"] ** 0.5, cfg["beta_end"] ** 0.5, T, dtype=np.float64) ** 2
    return np.cumprod(1.0 - betas)


def timesteps_for(cfg, n):
    T = cfg["num_train_timesteps"]
    if cfg["spacing"] == "trailing":
        # Written as T - i*T/n (not np.arange, which yields n+1 values for some n, e.g. 61).
        return np.round(T - np.arange(n) * (T / n)) - 1.0
    if cfg["spacing"] == "leading":
        ratio = T // n
        return (np.arange(n) * ratio)[::-1].astype(np.float64) + cfg["steps_offset"]
    return np.linspace(0, T - 1, n)[::-1].copy()


def model_v(x_in, t, k, cond):
    """The synthetic denoiser: depends on the scaled input, the timestep and the element index."""
    if cond:
        return 0.3 * x_in + 0.1 * np.cos(0.004 * t + 0.05 * k)
    return 0.25 * x_in - 0.05 * np.sin(0.003 * t)


def run_case(case):
    cfg, n, size = case["config"], case["steps"], case["size"]
    ac = alphas_cumprod(cfg)
    ts = timesteps_for(cfg, n)
    all_sigmas = np.sqrt((1.0 - ac) / ac)
    sigmas = np.concatenate([np.interp(ts, np.arange(len(ac)), all_sigmas), [0.0]])
    init_sigma = sigmas.max() if cfg["spacing"] != "leading" else math.sqrt(sigmas.max() ** 2 + 1.0)
    noise = Gaussian(case["seed"])
    x = noise.draw(size) * init_sigma
    k = np.arange(size, dtype=np.float64)
    g = case["guidance"]
    for i in range(n):
        s, s_next, t = sigmas[i], sigmas[i + 1], ts[i]
        x_in = x / math.sqrt(s * s + 1.0)
        v = model_v(x_in, t, k, True)
        if g > 1.0:
            vu = model_v(x_in, t, k, False)
            v = vu + g * (v - vu)
        x0 = x / (s * s + 1.0) - v * s / math.sqrt(s * s + 1.0)
        sigma_up = math.sqrt(s_next ** 2 * (s ** 2 - s_next ** 2) / s ** 2)
        sigma_down = math.sqrt(s_next ** 2 - sigma_up ** 2)
        x = x + (x - x0) / s * (sigma_down - s) + sigma_up * noise.draw(size)
    out = dict(case)
    out.update({"timesteps": ts.tolist(), "sigmas": sigmas.tolist(), "init_noise_sigma": float(init_sigma),
                "alphas_cumprod_first": float(ac[0]), "alphas_cumprod_last": float(ac[-1]),
                "final": x.tolist()})
    return out


def main():
    engine = MT19937_64(5489)
    for _ in range(9999):
        engine()
    assert engine() == 9981545732273789042, "MT19937-64 self-check failed"  # C++ [rand.predef]
    linear = {"num_train_timesteps": 1000, "beta_start": 0.00085, "beta_end": 0.012, "beta_schedule": "linear",
              "spacing": "trailing", "steps_offset": 1}
    cases = [
        {"name": "zero123plus_default", "config": linear, "steps": 28, "seed": 7, "guidance": 4.0, "size": 96},
        {"name": "scaled_linear_leading_no_cfg", "config": dict(linear, beta_schedule="scaled_linear",
                                                               spacing="leading"),
         "steps": 10, "seed": 11, "guidance": 1.0, "size": 64},
        {"name": "linspace_cfg", "config": dict(linear, spacing="linspace"), "steps": 7, "seed": 3,
         "guidance": 2.5, "size": 50},
        {"name": "one_step", "config": linear, "steps": 1, "seed": 5, "guidance": 3.0, "size": 33},
        {"name": "trailing_61", "config": linear, "steps": 61, "seed": 9, "guidance": 4.0, "size": 20},
    ]
    gaussian = Gaussian(42)
    result = {"noise_seed_42": [float(v) for v in gaussian.draw(9)], "cases": [run_case(c) for c in cases]}
    os.makedirs(os.path.dirname(os.path.abspath(sys.argv[1])), exist_ok=True)
    with open(sys.argv[1], "w") as f:
        json.dump(result, f)
    print(f"scheduler_reference: {len(cases)} cases written to {sys.argv[1]}")


if __name__ == "__main__":
    main()
