"""Wall time per step of every method at P = 1, 2, 3 on a 40 x 40 grid (L23 §5.1 square).

    python bench/methods_40x40.py [--steps 3]

Runs a few steps of convergence_square per method and order (no output written) and prints
ms/step and us per dof per step. DGMPM (first order) is listed with 1 and 4 particles per cell.
"""
import argparse

from skdgmpm.run import run
from skdgmpm.study import L23_LAYOUT


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument("--steps", type=int, default=3)
    parser.add_argument("--cells", type=int, default=40)
    args = parser.parse_args()
    n = args.cells
    cases = [("dgmpm", 1, ['method.integrator="euler"', "particles.per_cell=1"]),
             ("dgmpm", 1, ['method.integrator="euler"', "particles.per_cell=2"])]
    for order in (1, 2, 3):
        cases += [("rk-dgfem", order, ['method.integrator="rk2"' if order == 1 else 'method.integrator="rk4"']),
                  ("ader-dgfem", order, []),
                  ("ader-dgmpm", order, [f"particles.per_cell={L23_LAYOUT[order]}"])]
    print(f"{'method':<12}{'P':>2}{'variant':>42}{'dofs':>9}{'ms/step':>10}{'us/dof/step':>13}")
    for name, order, extra in cases:
        r = run("convergence_square", [f'method.name="{name}"', f"method.order={order}",
                                       f"grid.cells=[{n},{n}]", "run.t_end=1.0", "method.cfl=0.5", *extra],
                progress=False, frames=1, max_steps=args.steps)
        s = r.summary()
        per_step = s["wall_s"] / s["steps"]
        print(f"{name:<12}{order:>2}{' '.join(extra):>42}{s['dofs']:>9}{1e3 * per_step:>10.1f}"
              f"{1e6 * per_step / s['dofs']:>13.3f}")


if __name__ == "__main__":
    main()
