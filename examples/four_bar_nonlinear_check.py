"""Is the linear steady state of the thesis four-bar right? Run the full nonlinear model from the
linear periodic state for five periods and from rest, and compare.

Run: python examples/four_bar_nonlinear_check.py
"""

import studies
from studies import MechanismProblem


def main(n_steps: int = 256, from_rest: bool = True):
    problem = MechanismProblem.from_scene("four_bar_thesis")
    return studies.nonlinear_check(problem, n_steps=n_steps, n_periods=5, from_rest=from_rest,
                                   max_periods_from_rest=60)


if __name__ == "__main__":
    check = main()
    for spec, difference in check.difference.items():
        print(f"{spec}: nonlinear - linear {difference:.3g} {check.units[spec]} "
              f"({100 * check.relative_difference[spec]:.3g} % of peak to peak), periodicity defect "
              f"{check.periodicity_defect[spec]:.3g}")
    print(f"linear {check.linear_run_time:.3g} s, nonlinear from the linear state "
          f"{check.nonlinear_run_time:.3g} s, from rest {check.rest_run_time:.3g} s "
          f"(steady after {check.periods_to_steady} periods)")
