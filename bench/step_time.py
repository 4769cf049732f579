"""Wall time per step of the paper scenes (no output written).

    python bench/step_time.py [--repeat 3]

Prints, per scene and variant: steps, wall time per step, particles, dofs, and the time per
degree of freedom per step. Timings are measurements on the machine at hand, not test results.
"""
import argparse

from skdgmpm.run import run

CASES = [
    ("bar_elastic_1d", []),
    ("bar_svk_1d", []),
    ("plane_wave_svk_2d", []),
    ("partial_impact_2d", []),
    ("plate_impact_neohookean_2d", ['method.transverse="ctu"', "method.cfl=1.0"]),
    ("plate_impact_neohookean_2d", ['method.transverse="dcu"', "method.cfl=0.7", "method.cfl_above_limit=true"]),
]


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument("--repeat", type=int, default=3)
    args = parser.parse_args()
    print(f"{'scene':<28} {'variant':<34} {'steps':>6} {'ms/step':>8} {'particles':>9} {'dofs':>6} {'us/dof/step':>11}")
    for name, overrides in CASES:
        best = None
        for _ in range(args.repeat):
            r = run(name, overrides, progress=False)
            best = min(best or 1e9, r.wall_s)
        s = r.summary()
        per_step = best / s["steps"]
        print(f"{name:<28} {' '.join(overrides) or '(scene)':<34} {s['steps']:>6} {1e3 * per_step:>8.2f} "
              f"{s['particles']:>9} {s['dofs']:>6} {1e6 * per_step / s['dofs']:>11.3f}")


if __name__ == "__main__":
    main()
