"""Regenerate the README's picture: the main job's speed sweep of the default scene, as ``flexvib run``
computes it and ``flexvib plot`` draws it (a real result, nothing retouched).

Run from the repository's root: ``.venv/bin/python docs/make_figures.py`` (a few seconds once the
kernels are compiled); it writes ``docs/figures/four_bar_ritz_sweep.png`` and prints the sweep's
summary line.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

import studies

#: The sweep of ``mechanisms/scenes/four_bar_ritz.toml``'s ``[studies.sweep]`` table.
SCENE, START, STOP, COUNT, N_STEPS = "four_bar_ritz", 20.0, 240.0, 111, 256
OUT = Path(__file__).resolve().parent / "figures" / f"{SCENE}_sweep.png"


def main(out: Path = OUT) -> Path:
    problem = studies.MechanismProblem.from_scene(SCENE)
    sweep = studies.sweep(problem, "speed", np.linspace(START, STOP, COUNT), n_steps=N_STEPS)
    drawing = sweep.plot()
    out.parent.mkdir(parents=True, exist_ok=True)
    drawing.figure.savefig(out, dpi=80)   # small: about 50 kB
    print(f"{SCENE}: {sweep.message}")
    print(f"wrote {out}")
    return out


if __name__ == "__main__":
    main()
