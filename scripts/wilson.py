"""The Wilson score interval of a rate, for the scripts that print tables
(the Rust side's is atmo-sim `monte_carlo::wilson_95`)."""
import math


def wilson(k, n, z=1.959963984540054):
    """95 % interval (low, high) of k successes in n trials."""
    p = k / n
    d = 1 + z * z / n
    c = (p + z * z / (2 * n)) / d
    h = z / d * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n))
    return max(0.0, c - h), min(1.0, c + h)
