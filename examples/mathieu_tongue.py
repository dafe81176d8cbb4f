"""The principal instability tongue of the undamped Mathieu equation
x'' + w0^2 (1 + epsilon cos(W t)) x = 0 found by a speed sweep of the spectral radius.

Run: python examples/mathieu_tongue.py
"""

import numpy as np

import studies


def main(epsilon: float = 0.4, count: int = 101):
    problem = studies.mathieu_problem(epsilon=epsilon, damping_ratio=0.0, force=0.0)
    return studies.sweep(problem, "speed", np.linspace(1.5, 2.5, count), n_steps=128)


if __name__ == "__main__":
    for start, end in main().instabilities:
        print(f"unstable for speed in [{start:.4f}, {end:.4f}] rad/s")
