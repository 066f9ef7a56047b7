"""A tiny delayed plate/ball plant for control unit tests: x'' = -k g u(t - delay) per axis."""
from collections import deque

import numpy as np

K_G = 0.6 * 9.81


class DelayedPlant:
    def __init__(self, x0=(0.0, 0.0), v0=(0.0, 0.0), delay_s=0.0, dt_s=0.001, k_g=K_G):
        self.p, self.v = np.array(x0, float), np.array(v0, float)
        self.dt, self.k_g = dt_s, k_g
        self.queue = deque([np.zeros(2)] * int(round(delay_s / dt_s)))

    def advance(self, u, duration_s):
        for _ in range(int(round(duration_s / self.dt))):
            self.queue.append(np.asarray(u, float))
            a = -self.k_g * self.queue.popleft()
            self.p += self.v * self.dt + 0.5 * a * self.dt ** 2
            self.v += a * self.dt
