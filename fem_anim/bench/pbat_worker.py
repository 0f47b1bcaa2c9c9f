"""The hanging beam in pbatoolkit, run in pbatoolkit's own virtual environment.

Imports only numpy, scipy and pbatoolkit (never fem_anim: its environment holds
another numpy), so :mod:`fem_anim.bench.peers` runs it as a script in a subprocess::

    PEER_PYTHON pbat_worker.py IN.npz OUT.npz

``IN.npz`` holds the mesh (``X`` (n, 3), ``T`` (m, 4)), ``pinned`` vertex indices, ``tip``
vertex indices, ``rho``, ``youngs``, ``nu``, ``gravity`` (3,), ``dt``, ``steps``, ``rtol``,
``atol``, ``mode`` (``"newton"`` or ``"vbd"``) and ``sweeps``. ``OUT.npz`` gets the per-step
wall times, Newton iterations and the tip's mean displacement per step.

* ``newton``: implicit Euler, g(x) = 1/2 ||x - y||_M^2 + h^2 (U(x) - f.x), pbatoolkit's
  compiled stable neo-Hookean potential, gradient and exact Hessian
  (``pbat.fem.hyper_elastic_potential``), its consistent mass matrix, Eigen's simplicial
  LDL^T with AMD ordering (analysed once, factorised per iteration), backtracking line
  search, stopping at ||grad|| <= max(atol, rtol ||grad_0||) like fem_anim's SNES.
* ``vbd``: pbatoolkit's vertex block descent integrator (Chen et al. 2024) with ``sweeps``
  iterations per step (approximate: it stops after a fixed number of sweeps).
"""

import sys
import time

import numpy as np
import scipy.sparse as sp

import pbatoolkit
from pbatoolkit import pbat


def _lame(youngs, nu):
    """pbatoolkit's Lame parameters, with lambda + mu for its stable neo-Hookean.

    pbatoolkit's energy is mu/2 (I_C - 3) + lambda/2 (J - 1 - mu/lambda)^2 (Smith et al.'s
    form without the log term, no parameter remapping); its rest Hessian is linear
    elasticity with (mu, lambda - mu), so lambda + mu gives the same small-strain response
    as fem_anim's stable neo-Hookean with (mu, lambda).
    """
    mu, lam = pbatoolkit.pypbat.fem.lame_coefficients(youngs, nu)
    return mu, lam + mu


def _setup(X, T, rho, youngs, nu):
    E = np.asfortranarray(T.T.astype(np.int64))
    Xf = np.asfortranarray(X.T)
    element = pbat.fem.Element.Tetrahedron
    wg = pbat.fem.mesh_quadrature_weights(E, Xf, element, order=1, quadrature_order=1)
    eg = pbat.fem.mesh_quadrature_elements(E, wg)
    GNeg = pbat.fem.shape_function_gradients(E, Xf, element, order=1, dims=3,
                                             quadrature_order=1)
    mu, lam = _lame(youngs, nu)
    wg, eg = wg.ravel(order="F"), eg.ravel(order="F")
    M = pbat.fem.mass_matrix(E, Xf, rho=rho, dims=3, element=element, order=1)
    return E, Xf, element, wg, eg, GNeg, np.full(wg.size, mu), np.full(wg.size, lam), M


def run_newton(data):
    X, T, dt, steps = data["X"], data["T"], float(data["dt"]), int(data["steps"])
    E, Xf, element, wg, eg, GNeg, mug, lamg, M = _setup(
        X, T, float(data["rho"]), float(data["youngs"]), float(data["nu"]))
    n = X.shape[0]
    M = sp.csc_matrix(M)
    f = M @ np.tile(data["gravity"], n)
    free = np.ones(3 * n, bool)
    free[(3 * data["pinned"][:, None] + np.arange(3)).ravel()] = False
    x, v = X.ravel().copy(), np.zeros(3 * n)
    h2 = dt * dt
    flags = (pbat.fem.ElementElasticityComputationFlags.Potential
             | pbat.fem.ElementElasticityComputationFlags.Gradient)
    hflags = flags | pbat.fem.ElementElasticityComputationFlags.Hessian

    def evaluate(x, which):
        return pbat.fem.hyper_elastic_potential(
            E, n, eg, wg, GNeg, mug, lamg, x, energy=pbat.fem.StableNeoHookean, flags=which,
            spd_correction=pbat.fem.NoCorrection, element=element, order=1, dims=3)

    def objective(x, y):
        U = evaluate(x, pbat.fem.ElementElasticityComputationFlags.Potential)[0]
        r = x - y
        return 0.5 * r @ (M @ r) + h2 * (U - f @ x)

    solver, times, its, tip = None, [], [], []
    # every vertex-pair 3x3 block, as tiny values: scipy's sum drops entries that cancel to
    # 0, and Eigen's factorisation must see the pattern it analysed
    vertex_pattern = sp.csr_matrix(M[::3, ::3] != 0, dtype=float)
    pattern = sp.kron(vertex_pattern, np.ones((3, 3)), format="csr") * 1e-300
    for _ in range(steps):
        start = time.perf_counter()
        y = x + dt * v
        xk = x.copy()
        g0 = None
        for it in range(50):
            U, grad, H = evaluate(xk, hflags)
            r = M @ (xk - y) + h2 * (grad - f)
            rf = r[free]
            norm = np.linalg.norm(rf)
            g0 = norm if g0 is None else g0
            if norm <= max(float(data["atol"]), float(data["rtol"]) * g0):
                break
            A = sp.csc_matrix((M + h2 * H + pattern)[free][:, free])
            if solver is None:
                solver = pbat.math.linalg.SimplicialLdlt_Csc_AMD()
                solver.analyze(A)
            solver.factorize(A)
            p = np.zeros_like(xk)
            p[free] = -solver.solve(rf)
            gk, alpha = objective(xk, y), 1.0
            slope = r @ p
            while alpha > 1e-10:
                trial = xk + alpha * p
                gt = objective(trial, y)
                if np.isfinite(gt) and gt <= gk + 1e-4 * alpha * slope + 1e-12 * abs(gk):
                    break
                alpha *= 0.5
            xk = trial
        v = (xk - x) / dt
        x = xk
        times.append(time.perf_counter() - start)
        its.append(it)
        tip.append((x - X.ravel()).reshape(-1, 3)[data["tip"]].mean(axis=0))
    return np.array(times), np.array(its), np.array(tip)


def run_vbd(data):
    X, T, dt, steps = data["X"], data["T"], float(data["dt"]), int(data["steps"])
    n, m = X.shape[0], T.shape[0]
    mu, lam = _lame(float(data["youngs"]), float(data["nu"]))
    vbd = pbat.sim.vbd
    built = (vbd.Data()
             .with_volume_mesh(np.asfortranarray(X.T), np.asfortranarray(T.T.astype(np.int64)))
             .with_material(np.full(m, float(data["rho"])), np.full(m, mu), np.full(m, lam))
             .with_acceleration(np.asfortranarray(np.tile(data["gravity"][:, None], (1, n))))
             .with_dirichlet_vertices(np.sort(data["pinned"]).astype(np.int64))
             .construct(validate=True))
    integrator = vbd.Integrator(built)
    times, tip = [], []
    for _ in range(steps):
        start = time.perf_counter()
        integrator.step(dt, int(data["sweeps"]), 1)
        times.append(time.perf_counter() - start)
        x = np.asarray(integrator.x).T
        tip.append((x - X)[data["tip"]].mean(axis=0))
    return np.array(times), np.full(steps, int(data["sweeps"])), np.array(tip)


def main(argv):
    data = dict(np.load(argv[0], allow_pickle=False))
    mode = str(data["mode"])
    times, its, tip = run_newton(data) if mode == "newton" else run_vbd(data)
    np.savez(argv[1], times=times, iterations=its, tip=tip)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
