"""The benchmark block shared by the peers; the same as studies/examples/throughput.rs (keep in sync).

m particles per direction (m even, m^D ~ N), 2 per cell per direction, block b = m/2 cells wide,
g = 4 + m/16 empty cells on every side, n = b + 2g cells per direction on [0,1]^D, h = 1/n.
Neo-Hookean rho = 1000, E = 1e5, nu = 0.3; volume (h/2)^D. Velocity
v_a = v0 (sin(pi xi_{a+1 mod D}) - xi_a / 2), xi = (x - 1/2) / (b h / 2), v0 = 0.01 c,
c = sqrt((lambda + 2 mu) / rho). dt = 0.4 h / (c + 1.5 sqrt(D) v0). Particles x fastest.
"""

import argparse
import math

HEADER = (
    "engine,dim,method,vc,transfer,particles,cells,threads,steps,dt,seconds,"
    "particle_steps_per_s,kinetic_energy,setup_seconds"
)

DENSITY = 1000.0
YOUNG = 1e5
POISSON = 0.3
CFL = 0.4


def per_direction(n, dim):
    m = int(round(n ** (1.0 / dim)))
    m = max(m, 4)
    return (m + 1) // 2 * 2


class Block:
    def __init__(self, particles, dim):
        import numpy as np  # only the peers need it (run_matrix.py runs without)

        self.dim = dim
        m = per_direction(particles, dim)
        self.m = m
        b = m // 2
        g = 4 + m // 16
        self.n = b + 2 * g
        self.h = 1.0 / self.n
        h = self.h
        self.mu = YOUNG / (2.0 * (1.0 + POISSON))
        self.lam = YOUNG * POISSON / ((1.0 + POISSON) * (1.0 - 2.0 * POISSON))
        c = math.sqrt((self.lam + 2.0 * self.mu) / DENSITY)
        v0 = 0.01 * c
        self.dt = CFL * h / (c + 1.5 * math.sqrt(dim) * v0)
        self.count = m**dim
        self.volume = (h / 2.0) ** dim
        self.mass = DENSITY * self.volume
        # Lattice indices, x fastest (column 0 varies fastest).
        idx = np.indices((m,) * dim).reshape(dim, -1)[::-1].T  # (count, dim), x fastest
        x = (g + (idx + 0.5) / 2.0) * h
        half = b * h / 2.0
        xi = (x - 0.5) / half
        v = np.empty_like(x)
        for a in range(dim):
            v[:, a] = v0 * (np.sin(math.pi * xi[:, (a + 1) % dim]) - 0.5 * xi[:, a])
        self.x = np.ascontiguousarray(x, dtype=np.float64)
        self.v = np.ascontiguousarray(v, dtype=np.float64)


def arguments(description):
    p = argparse.ArgumentParser(description=description)
    p.add_argument("--dim", type=int, default=2, choices=[2, 3])
    p.add_argument("--particles", type=int, default=65536)
    p.add_argument("--steps", type=int, default=50)
    p.add_argument("--warmup", type=int, default=2)
    p.add_argument("--threads", type=int, default=1)
    p.add_argument("--header", action="store_true")
    return p.parse_args()


def report(engine, args, blk, threads, steps, seconds, velocities, setup_seconds):
    import numpy as np

    ke = 0.5 * blk.mass * float(np.sum(velocities * velocities))
    if args.header:
        print(HEADER)
    print(
        f"{engine},{blk.dim},bspline2,mp,apic,{blk.count},{blk.n},{threads},{steps},"
        f"{blk.dt:.6e},{seconds:.6f},{blk.count * steps / seconds:.6e},{ke:.12e},{setup_seconds:.3f}",
        flush=True,
    )
