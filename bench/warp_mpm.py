"""Peer benchmark: 2D/3D quadratic B-spline MLS-MPM (APIC) with neo-Hookean, f64, on NVIDIA Warp's
CPU backend (single-threaded). Same block, grid, material, dt and steps as
studies/examples/throughput.rs (bench/block.py). Prints one CSV line like the rkmpm example.

Step: clear grid; P2G (momentum m v + (m C - dt V0 4/h^2 tau) (x_i - x_p), mass; tau the Kirchhoff
stress mu (F F^T - I) + lambda ln J I, plane strain in 2D); grid velocity = momentum / mass
(no gravity, free faces); G2P (v, C = 4/h^2 sum w v_i (x_i - x_p)^T, F <- (I + dt C) F, x += dt v).

    python bench/warp_mpm.py --dim 2 --particles 65536 --steps 50
"""

import os
import sys
import time

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from block import Block, arguments, report  # noqa: E402

import numpy as np  # noqa: E402
import warp as wp  # noqa: E402

f64 = wp.float64

# Node offsets 0, 1, 2 as float64 (indexed by the loop variables: Warp 1.19 mistypes
# float64(loop index) inside the 3D triple loop, which it does not unroll).
OFFSETS = wp.constant(wp.vec3d(0.0, 1.0, 2.0))


@wp.func
def qweights(f: wp.float64):
    a = f64(1.5) - f
    b = f - f64(1.0)
    c = f - f64(0.5)
    return wp.vec3d(f64(0.5) * a * a, f64(0.75) - b * b, f64(0.5) * c * c)


@wp.kernel
def p2g2(
    x: wp.array(dtype=wp.vec2d),
    v: wp.array(dtype=wp.vec2d),
    C: wp.array(dtype=wp.mat22d),
    F: wp.array(dtype=wp.mat22d),
    gm: wp.array2d(dtype=wp.float64),
    gp: wp.array2d(dtype=wp.vec2d),
    inv_h: wp.float64,
    h: wp.float64,
    dt: wp.float64,
    vol: wp.float64,
    pm: wp.float64,
    mu: wp.float64,
    lam: wp.float64,
):
    p = wp.tid()
    X = x[p] * inv_h
    bx = int(X[0] - f64(0.5))
    by = int(X[1] - f64(0.5))
    fx = X[0] - f64(bx)
    fy = X[1] - f64(by)
    wx = qweights(fx)
    wy = qweights(fy)
    Fp = F[p]
    J = wp.determinant(Fp)
    eye = wp.identity(n=2, dtype=wp.float64)
    tau = mu * (Fp @ wp.transpose(Fp) - eye) + (lam * wp.log(J)) * eye
    affine = (-dt * vol * f64(4.0) * inv_h * inv_h) * tau + pm * C[p]
    mv = pm * v[p]
    for i in range(3):
        for j in range(3):
            dpos = wp.vec2d((OFFSETS[i] - fx) * h, (OFFSETS[j] - fy) * h)
            wt = wx[i] * wy[j]
            wp.atomic_add(gp, bx + i, by + j, wt * (mv + affine @ dpos))
            wp.atomic_add(gm, bx + i, by + j, wt * pm)


@wp.kernel
def grid2(gm: wp.array2d(dtype=wp.float64), gp: wp.array2d(dtype=wp.vec2d)):
    i, j = wp.tid()
    m = gm[i, j]
    if m > f64(0.0):
        gp[i, j] = gp[i, j] / m


@wp.kernel
def g2p2(
    x: wp.array(dtype=wp.vec2d),
    v: wp.array(dtype=wp.vec2d),
    C: wp.array(dtype=wp.mat22d),
    F: wp.array(dtype=wp.mat22d),
    gp: wp.array2d(dtype=wp.vec2d),
    inv_h: wp.float64,
    h: wp.float64,
    dt: wp.float64,
):
    p = wp.tid()
    X = x[p] * inv_h
    bx = int(X[0] - f64(0.5))
    by = int(X[1] - f64(0.5))
    fx = X[0] - f64(bx)
    fy = X[1] - f64(by)
    wx = qweights(fx)
    wy = qweights(fy)
    nv = wp.vec2d()
    nC = wp.mat22d()
    for i in range(3):
        for j in range(3):
            dpos = wp.vec2d((OFFSETS[i] - fx) * h, (OFFSETS[j] - fy) * h)
            wt = wx[i] * wy[j]
            gv = gp[bx + i, by + j]
            nv += wt * gv
            nC += (wt * f64(4.0) * inv_h * inv_h) * wp.outer(gv, dpos)
    v[p] = nv
    C[p] = nC
    F[p] = (wp.identity(n=2, dtype=wp.float64) + dt * nC) @ F[p]
    x[p] = x[p] + dt * nv


@wp.kernel
def p2g3(
    x: wp.array(dtype=wp.vec3d),
    v: wp.array(dtype=wp.vec3d),
    C: wp.array(dtype=wp.mat33d),
    F: wp.array(dtype=wp.mat33d),
    gm: wp.array3d(dtype=wp.float64),
    gp: wp.array3d(dtype=wp.vec3d),
    inv_h: wp.float64,
    h: wp.float64,
    dt: wp.float64,
    vol: wp.float64,
    pm: wp.float64,
    mu: wp.float64,
    lam: wp.float64,
):
    p = wp.tid()
    X = x[p] * inv_h
    bx = int(X[0] - f64(0.5))
    by = int(X[1] - f64(0.5))
    bz = int(X[2] - f64(0.5))
    fx = X[0] - f64(bx)
    fy = X[1] - f64(by)
    fz = X[2] - f64(bz)
    wx = qweights(fx)
    wy = qweights(fy)
    wz = qweights(fz)
    Fp = F[p]
    J = wp.determinant(Fp)
    eye = wp.identity(n=3, dtype=wp.float64)
    tau = mu * (Fp @ wp.transpose(Fp) - eye) + (lam * wp.log(J)) * eye
    affine = (-dt * vol * f64(4.0) * inv_h * inv_h) * tau + pm * C[p]
    mv = pm * v[p]
    for i in range(3):
        for j in range(3):
            for k in range(3):
                ii = bx + i
                jj = by + j
                kk = bz + k
                dpos = wp.vec3d((OFFSETS[i] - fx) * h, (OFFSETS[j] - fy) * h, (OFFSETS[k] - fz) * h)
                wt = wx[i] * wy[j] * wz[k]
                wp.atomic_add(gp, ii, jj, kk, wt * (mv + affine @ dpos))
                wp.atomic_add(gm, ii, jj, kk, wt * pm)


@wp.kernel
def grid3(gm: wp.array3d(dtype=wp.float64), gp: wp.array3d(dtype=wp.vec3d)):
    i, j, k = wp.tid()
    m = gm[i, j, k]
    if m > f64(0.0):
        gp[i, j, k] = gp[i, j, k] / m


@wp.kernel
def g2p3(
    x: wp.array(dtype=wp.vec3d),
    v: wp.array(dtype=wp.vec3d),
    C: wp.array(dtype=wp.mat33d),
    F: wp.array(dtype=wp.mat33d),
    gp: wp.array3d(dtype=wp.vec3d),
    inv_h: wp.float64,
    h: wp.float64,
    dt: wp.float64,
):
    p = wp.tid()
    X = x[p] * inv_h
    bx = int(X[0] - f64(0.5))
    by = int(X[1] - f64(0.5))
    bz = int(X[2] - f64(0.5))
    fx = X[0] - f64(bx)
    fy = X[1] - f64(by)
    fz = X[2] - f64(bz)
    wx = qweights(fx)
    wy = qweights(fy)
    wz = qweights(fz)
    nv = wp.vec3d()
    nC = wp.mat33d()
    for i in range(3):
        for j in range(3):
            for k in range(3):
                gv = gp[bx + i, by + j, bz + k]
                dpos = wp.vec3d((OFFSETS[i] - fx) * h, (OFFSETS[j] - fy) * h, (OFFSETS[k] - fz) * h)
                wt = wx[i] * wy[j] * wz[k]
                nv += wt * gv
                nC += (wt * f64(4.0) * inv_h * inv_h) * wp.outer(gv, dpos)
    v[p] = nv
    C[p] = nC
    F[p] = (wp.identity(n=3, dtype=wp.float64) + dt * nC) @ F[p]
    x[p] = x[p] + dt * nv


def main():
    args = arguments(__doc__)
    wp.config.quiet = True
    wp.init()
    setup = time.perf_counter()
    d = args.dim
    blk = Block(args.particles, d)
    dev = "cpu"
    vec = wp.vec2d if d == 2 else wp.vec3d
    mat = wp.mat22d if d == 2 else wp.mat33d
    n = blk.count
    x = wp.array(blk.x, dtype=vec, device=dev)
    v = wp.array(blk.v, dtype=vec, device=dev)
    C = wp.zeros(n, dtype=mat, device=dev)
    F = wp.array(np.tile(np.eye(d), (n, 1, 1)), dtype=mat, device=dev)
    shape = (blk.n + 3,) * d
    gm = wp.zeros(shape, dtype=wp.float64, device=dev)
    gp = wp.zeros(shape, dtype=vec, device=dev)
    h = f64(blk.h)
    inv_h = f64(1.0 / blk.h)
    dt = f64(blk.dt)
    p2g, grid, g2p = (p2g2, grid2, g2p2) if d == 2 else (p2g3, grid3, g2p3)
    pargs = [x, v, C, F, gm, gp, inv_h, h, dt, f64(blk.volume), f64(blk.mass), f64(blk.mu), f64(blk.lam)]

    def step():
        gm.zero_()
        gp.zero_()
        wp.launch(p2g, dim=n, inputs=pargs, device=dev)
        wp.launch(grid, dim=shape, inputs=[gm, gp], device=dev)
        wp.launch(g2p, dim=n, inputs=[x, v, C, F, gp, inv_h, h, dt], device=dev)

    for _ in range(args.warmup):  # includes compiling the kernels
        step()
    wp.synchronize()
    setup_seconds = time.perf_counter() - setup
    t0 = time.perf_counter()
    for _ in range(args.steps):
        step()
    wp.synchronize()
    seconds = time.perf_counter() - t0
    report("warp", args, blk, 1, args.steps, seconds, v.numpy(), setup_seconds)


if __name__ == "__main__":
    main()
