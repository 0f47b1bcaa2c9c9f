# %% [markdown]
# # The harmonic oscillator, three integrators side by side
#
# The seed's first example (section 1.1): a mass m on a spring of stiffness k,
#
#     m x'' = f(x) = -k x,    E(x) = k/2 x^2,    omega = sqrt(k/m),
#
# whose energy H = 1/2 m v^2 + 1/2 k x^2 is constant. Every scheme of the project is one
# minimisation per step (seed eq. 4),
#
#     x_{n+1} = argmin_x  g(x) = m/2 (x - y)^2 + w E(x),
#
# with the predictor y and weight w of `fem_anim.simulation.integrators.Integrator` (the same objects the
# finite-element time loop uses): Newmark y = x_n + h v_n + h^2/4 a_n, w = h^2/4; implicit
# Euler y = x_n + h v_n, w = h^2; symplectic Euler the same with E linearised at x_n, so
# g = m/2 (x - y)^2 + h^2 E'(x_n) x. For this quadratic E one Newton step from any point is the
# exact minimiser, x = (m y) / (m + w k) (symplectic: x = y - w k x_n / m); the integrator's
# `update` then gives v_{n+1} (and a_{n+1}).
#
# What each scheme does to the energy, asserted below:
#
# * **implicit Euler** multiplies z = omega x + i v by 1/(1 + i omega h) per step: H decays by
#   exactly 1/(1 + (omega h)^2) every step (numerical dissipation);
# * **Newmark** (the trapezoidal rule) multiplies z by (1 - i omega h/2)/(1 + i omega h/2), a
#   number of modulus one: H is conserved to round-off;
# * **symplectic Euler** conserves the shadow energy Q = v^2 + omega^2 x^2 - h omega^2 x v
#   exactly, so H oscillates within [(1 - omega h/2)/(1 + omega h/2),
#   (1 + omega h/2)/(1 - omega h/2)] times H_0 and never drifts (stable for omega h < 2).
#
# Parameters: m = 1 kg, k = 4 pi^2 N/m (period 1 s), x_0 = 0.1 m, v_0 = 0, h = 0.05 s,
# 10 periods. The full run also draws `out/demos/harmonic_oscillator.png` (energy over time;
# `demos/harmonic_oscillator.png`, shown in the README, is a copy).

# %%
import os
from pathlib import Path

import numpy as np

from fem_anim.simulation.integrators import Integrator, State

REDUCED = os.environ.get("FEM_ANIM_DEMO_REDUCED") == "1"
OUT = Path(os.environ.get("FEM_ANIM_DEMO_OUT", "out/demos"))
m, k = 1.0, 4.0 * np.pi**2  # kg, N/m
omega = np.sqrt(k / m)
x0, h, periods = 0.1, 0.05, 10
steps = int(round(periods * 2 * np.pi / omega / h))

# %% [markdown]
# ## The time loop: stage, minimise, update

# %%


def energy(state: State) -> float:
    return float(0.5 * m * state.v[0] ** 2 + 0.5 * k * state.u[0] ** 2)


def run(name: str) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    integrator = Integrator(name)
    state = State(u=np.array([x0]), v=np.zeros(1), a=np.array([-k * x0 / m]))
    xs, vs = [x0], [0.0]
    for _ in range(steps):
        y = integrator.predictor(h, state)
        w = integrator.weight(h, state)
        if integrator.scheme.explicit:  # E linearised at x_n: g = m/2 (x-y)^2 + w k x_n x
            x = y - w * k * state.u / m
        else:  # argmin m/2 (x-y)^2 + w k/2 x^2
            x = m * y / (m + w * k)
        state = integrator.update(h, state, x, y)
        xs.append(state.u[0])
        vs.append(state.v[0])
    xs, vs = np.array(xs), np.array(vs)
    return xs, vs, 0.5 * m * vs**2 + 0.5 * k * xs**2


results = {name: run(name) for name in ("implicit_euler", "newmark", "symplectic_euler")}
H0 = 0.5 * k * x0**2
t = h * np.arange(steps + 1)

# %% [markdown]
# ## What the run must show

# %%
x, v, H = results["implicit_euler"]
ratio = H[1:] / H[:-1]
assert np.allclose(ratio, 1.0 / (1.0 + (omega * h) ** 2), rtol=1e-12, atol=0.0), ratio
print(f"implicit Euler: H after {periods} periods = {H[-1] / H0:.3e} H_0 "
      f"(factor {1 / (1 + (omega * h) ** 2):.6f} per step)")

x, v, H = results["newmark"]
newmark_drift = np.abs(H / H0 - 1.0).max()
assert newmark_drift < 1e-13, newmark_drift
print(f"Newmark: max |H/H_0 - 1| = {newmark_drift:.1e}")

x, v, H = results["symplectic_euler"]
Q = v**2 + omega**2 * x**2 - h * omega**2 * x * v
shadow = np.abs(Q / Q[0] - 1.0).max()
assert shadow < 1e-13, shadow
s = omega * h / 2
assert np.all(H / H0 >= (1 - s) / (1 + s) - 1e-14) and np.all(H / H0 <= (1 + s) / (1 - s) + 1e-14)
per = int(round(2 * np.pi / omega / h))
first, last = H[:per].mean(), H[-per:].mean()
assert abs(last / first - 1.0) < 1e-2, (first, last)  # bounded oscillation, no drift
swing = np.abs(H / H0 - 1.0).max()
assert swing > 1e-2  # it does oscillate, by O(omega h)
print(f"symplectic Euler: H/H_0 in [{(H / H0).min():.4f}, {(H / H0).max():.4f}], "
      f"shadow energy kept to {shadow:.1e}, period means differ by {abs(last / first - 1):.1e}")

# %% [markdown]
# ## The picture (full run only)

# %%
if not REDUCED:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(8, 4.5))
    labels = {"implicit_euler": "implicit Euler (decays)", "newmark": "Newmark (conserved)",
              "symplectic_euler": "symplectic Euler (bounded oscillation)"}
    for name, (_, _, H) in results.items():
        ax.plot(t, H / H0, label=labels[name])
    ax.set_xlabel("time (s)")
    ax.set_ylabel("energy / initial energy")
    ax.set_title(f"Harmonic oscillator, omega h = {omega * h:.3f}")
    ax.legend()
    ax.grid(alpha=0.3)
    fig.tight_layout()
    OUT.mkdir(parents=True, exist_ok=True)
    fig.savefig(OUT / "harmonic_oscillator.png", dpi=100)
    print(f"picture {OUT / 'harmonic_oscillator.png'}")
