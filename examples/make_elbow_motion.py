"""Write examples/elbow_flexion.csv: a recorded-style elbow flexion to try fdbench on.

A minimum-jerk flexion from -50 deg to +40 deg over 2 s between two rests of 0.25 s (2.5 s in
all), sampled at 120 Hz as an optical motion-capture system would, with white noise of 0.3 deg
(seed 7) on the angle. Columns: t (s), theta (deg). Run it again to rebuild the file exactly.
"""

from pathlib import Path

import numpy as np

RATE_HZ, REST_S, MOVE_S = 120.0, 0.25, 2.0
START_DEG, END_DEG, NOISE_DEG, SEED = -50.0, 40.0, 0.3, 7


def minimum_jerk(t: np.ndarray) -> np.ndarray:
    """The flexion angle (deg) at times t (s)."""
    tau = np.clip((t - REST_S) / MOVE_S, 0.0, 1.0)
    return START_DEG + (END_DEG - START_DEG) * (10 * tau**3 - 15 * tau**4 + 6 * tau**5)


def main(path: Path = Path(__file__).with_name("elbow_flexion.csv")) -> None:
    t = np.arange(int(round((2 * REST_S + MOVE_S) * RATE_HZ)) + 1) / RATE_HZ
    theta = minimum_jerk(t) + NOISE_DEG * np.random.default_rng(SEED).standard_normal(len(t))
    lines = ["t,theta"] + [f"{a:.6f},{b:.4f}" for a, b in zip(t, theta)]
    path.write_text("\n".join(lines) + "\n")


if __name__ == "__main__":
    main()
