"""Peer benchmark: 2D/3D quadratic B-spline MLS-MPM (APIC) with neo-Hookean, f64, on Taichi's CPU
backend with --threads threads. Same block, grid, material, dt and steps as
studies/examples/throughput.rs (bench/block.py) and the same step as bench/warp_mpm.py. Prints one
CSV line like the rkmpm example.

    python bench/taichi_mpm.py --dim 2 --particles 65536 --steps 50 --threads 2
"""

import os
import sys
import time

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from block import Block, arguments, report  # noqa: E402

import numpy as np  # noqa: E402
import taichi as ti  # noqa: E402


def main():
    args = arguments(__doc__)
    ti.init(arch=ti.cpu, default_fp=ti.f64, cpu_max_num_threads=args.threads, log_level=ti.ERROR)
    setup = time.perf_counter()
    d = args.dim
    blk = Block(args.particles, d)
    n = blk.count
    x = ti.Vector.field(d, ti.f64, n)
    v = ti.Vector.field(d, ti.f64, n)
    C = ti.Matrix.field(d, d, ti.f64, n)
    F = ti.Matrix.field(d, d, ti.f64, n)
    shape = (blk.n + 3,) * d
    gm = ti.field(ti.f64, shape)
    gp = ti.Vector.field(d, ti.f64, shape)
    x.from_numpy(blk.x)
    v.from_numpy(blk.v)
    F.from_numpy(np.tile(np.eye(d), (n, 1, 1)))
    h = blk.h
    inv_h = 1.0 / h
    dt = blk.dt
    vol = blk.volume
    pm = blk.mass
    mu = blk.mu
    lam = blk.lam

    @ti.kernel
    def clear():
        for I in ti.grouped(gm):
            gm[I] = 0.0
            gp[I] = ti.Vector.zero(ti.f64, d)

    @ti.kernel
    def p2g():
        for p in x:
            X = x[p] * inv_h
            base = ti.cast(X - 0.5, ti.i32)
            fx = X - ti.cast(base, ti.f64)
            w = [0.5 * (1.5 - fx) ** 2, 0.75 - (fx - 1.0) ** 2, 0.5 * (fx - 0.5) ** 2]
            Fp = F[p]
            J = Fp.determinant()
            eye = ti.Matrix.identity(ti.f64, d)
            tau = mu * (Fp @ Fp.transpose() - eye) + lam * ti.log(J) * eye
            affine = (-dt * vol * 4.0 * inv_h * inv_h) * tau + pm * C[p]
            mv = pm * v[p]
            for off in ti.static(ti.grouped(ti.ndrange(*((3,) * d)))):
                dpos = (off.cast(ti.f64) - fx) * h
                wt = 1.0
                for a in ti.static(range(d)):
                    wt *= w[off[a]][a]
                gp[base + off] += wt * (mv + affine @ dpos)
                gm[base + off] += wt * pm

    @ti.kernel
    def grid():
        for I in ti.grouped(gm):
            m = gm[I]
            if m > 0.0:
                gp[I] = gp[I] / m

    @ti.kernel
    def g2p():
        for p in x:
            X = x[p] * inv_h
            base = ti.cast(X - 0.5, ti.i32)
            fx = X - ti.cast(base, ti.f64)
            w = [0.5 * (1.5 - fx) ** 2, 0.75 - (fx - 1.0) ** 2, 0.5 * (fx - 0.5) ** 2]
            nv = ti.Vector.zero(ti.f64, d)
            nC = ti.Matrix.zero(ti.f64, d, d)
            for off in ti.static(ti.grouped(ti.ndrange(*((3,) * d)))):
                dpos = (off.cast(ti.f64) - fx) * h
                wt = 1.0
                for a in ti.static(range(d)):
                    wt *= w[off[a]][a]
                gv = gp[base + off]
                nv += wt * gv
                nC += (wt * 4.0 * inv_h * inv_h) * gv.outer_product(dpos)
            v[p] = nv
            C[p] = nC
            F[p] = (ti.Matrix.identity(ti.f64, d) + dt * nC) @ F[p]
            x[p] += dt * nv

    def step():
        clear()
        p2g()
        grid()
        g2p()

    for _ in range(args.warmup):  # includes compiling the kernels
        step()
    ti.sync()
    setup_seconds = time.perf_counter() - setup
    t0 = time.perf_counter()
    for _ in range(args.steps):
        step()
    ti.sync()
    seconds = time.perf_counter() - t0
    report("taichi", args, blk, args.threads, args.steps, seconds, v.to_numpy(), setup_seconds)


if __name__ == "__main__":
    main()
