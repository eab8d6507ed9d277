"""Write sample_data/labels_300wlp.csv: synthetic 300W-LP labels for the convert/audit/draw demos.

Deterministic. Besides well-spread angles it holds the rows that trip tools up:
HELEN_2375918801_1_14's near-locked label, an exact gimbal lock, a non-canonical
triple (yaw 120), and a full-range (face turned away) rotation.
"""

from pathlib import Path

import numpy as np
import pandas as pd

OUT = Path(__file__).resolve().parents[1] / "sample_data" / "labels_300wlp.csv"


def main():
    rng = np.random.default_rng(2024)
    n = 200
    df = pd.DataFrame(
        {
            "image": [f"synth_{i:04d}.jpg" for i in range(n)],
            "pitch": rng.uniform(-60, 60, n).round(4),
            "yaw": rng.uniform(-89, 89, n).round(4),
            "roll": rng.uniform(-45, 45, n).round(4),
            "tdx": rng.uniform(150, 300, n).round(2),
            "tdy": rng.uniform(150, 300, n).round(2),
            "size": 80.0,
        }
    )
    special = pd.DataFrame(
        {
            "image": ["HELEN_2375918801_1_14.jpg", "exact_lock.jpg", "non_canonical.jpg", "turned_away.jpg"],
            "pitch": [-16.0909, 10.0, 20.0, -170.0],
            "yaw": [-89.99858, 90.0, 120.0, 30.0],
            "roll": [-6.8545, 5.0, 15.0, 160.0],
            "tdx": 225.0,
            "tdy": 225.0,
            "size": 80.0,
        }
    )
    OUT.parent.mkdir(exist_ok=True)
    pd.concat([df, special], ignore_index=True).to_csv(OUT, index=False)
    print(f"wrote {OUT}")


if __name__ == "__main__":
    main()
