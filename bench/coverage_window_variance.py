"""How much the coverage of an exact 95 % band varies from one held-out window to another when the errors persist
(docs/identifiability.md, "Posterior predictive bands").

The errors are a stationary Gaussian AR(1) of unit marginal sd whose correlation at one day is the real walls'
(the lag-1-day autocorrelation of their fitted-period residuals: 0.73 on TRH-1's interface, 0.56-0.71 on PASSYS's
probes); the band is the exact one, +-1.96. For windows of each wall's held-out length and sampling interval, the
share of windows whose coverage lies inside the issue's 85..99 %, above it and below it.

    PYTHONPATH=src python bench/coverage_window_variance.py
"""

from __future__ import annotations

import numpy as np
from scipy.signal import lfilter

#: name, samples per window, samples per day, correlation at one day
CASES = (
    ("TRH-1: 14 days at 10 min", 2016, 144, 0.73),
    ("PASSYS: 4 days at 5 min", 1152, 288, 0.65),
    ("synthetic campaigns: 2 days at 5 min, white errors", 576, 288, 0.0),
)


def window_coverages(n: int, per_day: int, acf_day: float, windows: int = 4000, seed: int = 0) -> np.ndarray:
    """Coverage of the exact 95 % band over ``windows`` independent windows of ``n`` samples."""
    rng = np.random.default_rng(seed)
    rho = acf_day ** (1.0 / per_day) if acf_day > 0 else 0.0
    spin = 10 * per_day  # start the recursion long before the window: stationary at its start
    w = rng.standard_normal((windows, n + spin)) * np.sqrt(1.0 - rho**2)
    x = lfilter([1.0], [1.0, -rho], w, axis=1)[:, spin:]
    return np.mean(np.abs(x) <= 1.959964, axis=1)


def main() -> None:
    for name, n, per_day, acf_day in CASES:
        cov = window_coverages(n, per_day, acf_day)
        print(
            f"{name} (correlation at one day {acf_day}): median coverage {np.median(cov):.3f}; windows above 99 % "
            f"{np.mean(cov > 0.99):.0%}, in 85..99 % {np.mean((cov >= 0.85) & (cov <= 0.99)):.0%}, below 85 % "
            f"{np.mean(cov < 0.85):.0%}"
        )


if __name__ == "__main__":
    main()
