# %% [markdown]
# # Gradient descent, Newton's method and affine invariance
#
# Every implicit time step minimises an objective g(x) (seed eq. 4-5). This demo, in numpy only,
# explains why the solver uses Newton's method and not gradient descent (GD), following
# seed section 3.2:
#
# 1. GD with exact line search on seed Example 2, g(x) = 1/2 (x1^2 + gamma x2^2) (eq. 7),
#    reproduces the closed-form iterates of eq. 8 and needs O(gamma) iterations.
# 2. Newton's method, p = -(hess g)^-1 grad g (eq. 10), solves the same problem in one step.
# 3. Newton's method and its decrement are affine invariant (Note 3, Definition 4); GD is not.
# 4. A picture of the GD zigzag against the single Newton step, for gamma = 10.
#
# Set FEM_ANIM_DEMO_REDUCED=1 for the short variant the test suite runs (it drops the largest
# gamma and caps the hopeless GD run sooner); the figure is written to
# $FEM_ANIM_DEMO_OUT/optimisation_basics.png (default out/demos).

# %%
import os
import time
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

REDUCED = os.environ.get("FEM_ANIM_DEMO_REDUCED") == "1"
OUT = Path(os.environ.get("FEM_ANIM_DEMO_OUT", "out/demos"))
GAMMAS = [2.0, 10.0, 100.0] if REDUCED else [2.0, 10.0, 100.0, 1000.0]
GD_CAP = 2_000 if REDUCED else 20_000  # iteration cap for GD on the badly scaled problem
started = time.perf_counter()

# %% [markdown]
# ## 1. Gradient descent with exact line search (seed Example 2)
# Write eq. 7 as g(x) = 1/2 x^T A x with A = diag(1, gamma). The GD direction is the residual
# r = -grad g = -A x, and the exact line search (Definition 3) minimises the parabola
# alpha -> g(x + alpha r), whose minimiser is alpha = r.r / r.A r. From x0 = (gamma, 1) the
# iterates are (eq. 8)
#
#   x1^k = gamma ((gamma - 1)/(gamma + 1))^k,   x2^k = (-(gamma - 1)/(gamma + 1))^k,
#
# so g shrinks by the factor q^2 = ((gamma - 1)/(gamma + 1))^2 per step and reaching
# g < 1e-10 g0 takes k = ceil(ln 1e-10 / ln q^2), about 5.8 gamma iterations for large gamma.

# %%
def gd_exact_quadratic(A, x0, steps=None, rtol=None):
    """GD with exact line search on 1/2 x^T A x: `steps` iterates, or until g < rtol g0."""
    xs, g0 = [x0], 0.5 * x0 @ A @ x0
    while (steps is not None and len(xs) <= steps) or \
            (rtol is not None and 0.5 * xs[-1] @ A @ xs[-1] >= rtol * g0):
        r = -A @ xs[-1]
        xs.append(xs[-1] + (r @ r) / (r @ A @ r) * r)
    return np.array(xs)


for gamma in GAMMAS:
    A, x0 = np.diag([1.0, gamma]), np.array([gamma, 1.0])
    q, k = (gamma - 1) / (gamma + 1), np.arange(51)
    eq8 = np.column_stack([gamma * q**k, (-q) ** k])
    xs = gd_exact_quadratic(A, x0, steps=50)
    rel = np.max(np.linalg.norm(xs - eq8, axis=1) / np.linalg.norm(eq8, axis=1))
    its = len(gd_exact_quadratic(A, x0, rtol=1e-10)) - 1
    predicted = int(np.ceil(np.log(1e-10) / np.log(q**2)))
    # 2. Newton (eq. 10): the quadratic model (eq. 9) is exact, so one step lands on x* = 0.
    x1_newton = x0 - np.linalg.solve(A, A @ x0)
    print(f"gamma = {gamma:6g}: eq. 8 max rel. error (k <= 50) {rel:.1e}, "
          f"GD its to g < 1e-10 g0: {its:5d} (predicted {predicted}), "
          f"Newton its: 1, |x1| = {np.linalg.norm(x1_newton):.1e}")
    assert rel < 1e-12, (gamma, rel)
    assert its == predicted, (gamma, its, predicted)
    assert np.linalg.norm(x1_newton) <= 1e-15 * np.linalg.norm(x0), x1_newton

# %% [markdown]
# ## 3. Affine invariance (seed Note 3, Definition 4)
# Take a smooth, strictly convex, non-quadratic g (a sum of exponentials, seed eq. 5) and a
# nonsingular T, and set g~(y) = g(T y). Then grad g~ = T^T grad g and
# hess g~ = T^T (hess g) T (the seed's "T^2" is T^T), so the Newton steps satisfy
# dy = -T^-1 (hess g)^-1 grad g = T^-1 dx, and from y0 = T^-1 x0 the iterates obey x_k = T y_k.
# The Newton decrement is lambda^2 = grad g^T (hess g)^-1 grad g = -grad g . dx (the seed's
# eq. 12 has a typo: g - lambda^2/2 is the minimum of the quadratic model (9), not lambda^2);
# it is invariant too, so the stopping test lambda^2/2 <= eps stops both runs at the same
# step. A backtracking (Armijo) line search keeps the invariance, since its test
# g(x + t dx) <= g(x) + c t grad g . dx only involves invariant numbers. GD is not invariant:
# its step -T^T grad g is not T^-1 times -grad g, and on g~ it crawls.
#
# That is exact arithmetic. In floating point, T = R1 D (rotation R1, scaling
# D = diag(1, 1e-4), cond 1e4) keeps x_k = T y_k to ~1e-14: the ill-conditioning is a scaling
# of the unknowns y, which floating point and Gaussian elimination do not notice. A general
# T = R1 D R2 mixes large and small y components, hess g~ has condition number up to
# cond(T)^2 cond(hess g), and the two runs then agree only to about eps cond(T)^2 ~ 1e-8:
# round-off, not a failure of the invariance. (lambda^2 is compared relative to
# max(lambda^2, 1e-10 lambda0^2): near x* it is a difference of round-off-sized numbers.)

# %%
a = np.array([[1.0, 3.0], [1.0, -3.0], [-1.0, 0.0]])  # g(x) = sum_i exp(a_i . x - 0.1)


def make(T):
    """Value, gradient and Hessian of g~(y) = g(T y)."""
    def value(y):
        return np.sum(np.exp(a @ (T @ y) - 0.1))

    def grad(y):
        return T.T @ (a.T @ np.exp(a @ (T @ y) - 0.1))

    def hess(y):
        return T.T @ (a.T * np.exp(a @ (T @ y) - 0.1)) @ a @ T
    return value, grad, hess


def descent(problem, y0, newton, eps=1e-12, maxit=100, f_star=None):
    """Damped Newton (stop at lambda^2/2 <= eps) or GD (stop at g - f_star <= eps)."""
    value, grad, hess = problem
    ys, lams = [y0], []
    for _ in range(maxit):
        y, gr = ys[-1], grad(ys[-1])
        d = -np.linalg.solve(hess(y), gr) if newton else -gr
        lams.append(-gr @ d)  # the Newton decrement lambda^2 (or |grad|^2 for GD)
        if (newton and lams[-1] / 2 <= eps) or (not newton and value(y) - f_star <= eps):
            break
        t = 1.0
        while value(y + t * d) > value(y) + 0.25 * t * (gr @ d):
            t *= 0.5
        ys.append(y + t * d)
    return np.array(ys), np.array(lams)


def rotation(theta):
    return np.array([[np.cos(theta), -np.sin(theta)], [np.sin(theta), np.cos(theta)]])


eps, D = np.finfo(float).eps, np.diag([1.0, 1e-4])
x0 = np.array([-1.0, 1.0])
xs, lam_x = descent(make(np.eye(2)), x0, newton=True)
for name, T in {"R1 D": rotation(0.4) @ D, "R1 D R2": rotation(0.4) @ D @ rotation(-1.1)}.items():
    tol = 1e-10 if name == "R1 D" else 10 * eps * np.linalg.cond(T) ** 2
    ys, lam_y = descent(make(T), np.linalg.solve(T, x0), newton=True)
    assert len(xs) == len(ys), (len(xs), len(ys))
    x_err = np.max(np.linalg.norm(xs - ys @ T.T, axis=1) / np.linalg.norm(xs, axis=1))
    lam_err = np.max(np.abs(lam_x - lam_y) / np.maximum(lam_x, 1e-10 * lam_x[0]))
    print(f"T = {name:7s} (cond {np.linalg.cond(T):.0e}): Newton its on g {len(xs) - 1}, "
          f"on g~ {len(ys) - 1}; max_k |x_k - T y_k|/|x_k| = {x_err:.1e}, "
          f"max_k rel. diff. of lambda^2 = {lam_err:.1e} (tolerance {tol:.0e})")
    assert x_err < tol and lam_err < tol, (name, x_err, lam_err)
print(f"  lambda^2 per Newton iterate: {' '.join(f'{v:.1e}' for v in lam_x)}")
assert lam_x[-1] / 2 <= 1e-12 and len(xs) - 1 <= 10
T = rotation(0.4) @ D
f_star = make(np.eye(2))[0](xs[-1])
gd_x, _ = descent(make(np.eye(2)), x0, newton=False, eps=1e-8, maxit=GD_CAP, f_star=f_star)
gd_y, _ = descent(make(T), np.linalg.solve(T, x0), newton=False, eps=1e-8, maxit=GD_CAP,
                  f_star=f_star)
gap_y = make(T)[0](gd_y[-1]) - f_star
print(f"GD its to g - g* <= 1e-8: on g {len(gd_x) - 1}; on g~ (T = R1 D) not reached after "
      f"{len(gd_y) - 1} its, g~ - g* = {gap_y:.2e} (at y0: {make(T)[0](gd_y[0]) - f_star:.2e})")
assert len(gd_x) - 1 <= 100 and len(gd_y) - 1 >= 100 * (len(gd_x) - 1) and gap_y > 1e-8

# %% [markdown]
# ## 4. The zigzag
# On the gamma = 10 contours of eq. 7, consecutive exact-line-search GD directions are
# orthogonal (r_{k+1} . r_k = 0), so the path zigzags towards x* = 0; Newton jumps there.

# %%
gamma = 10.0
A, x0 = np.diag([1.0, gamma]), np.array([gamma, 1.0])
path = gd_exact_quadratic(A, x0, rtol=1e-4)
X1, X2 = np.meshgrid(np.linspace(-1, 11, 300), np.linspace(-1.6, 1.6, 200))
fig, ax = plt.subplots(figsize=(8, 3.4))
ax.contour(X1, X2, 0.5 * (X1**2 + gamma * X2**2), levels=np.geomspace(1e-3, 60, 14),
           colors="0.7", linewidths=0.8)
ax.plot(path[:, 0], path[:, 1], "o-", ms=3, label=f"GD, exact line search ({len(path) - 1} its)")
ax.plot([x0[0], 0], [x0[1], 0], "s--", ms=5, label="Newton (1 step)")
ax.set(aspect="equal", xlabel="x1", ylabel="x2", title="seed Example 2, gamma = 10")
ax.legend(loc="upper left")
OUT.mkdir(parents=True, exist_ok=True)
tmp = OUT / f".optimisation_basics.{os.getpid()}.png"  # atomic: safe when run on several ranks
fig.savefig(tmp, dpi=120, bbox_inches="tight")
os.replace(tmp, OUT / "optimisation_basics.png")
assert (OUT / "optimisation_basics.png").stat().st_size > 0
print(f"picture {OUT / 'optimisation_basics.png'}; run time {time.perf_counter() - started:.2f} s")
