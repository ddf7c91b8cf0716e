"""The CSV writer's numbers as read back by Python's csv module (issue 55)."""

from __future__ import annotations

import numpy as np


def test_55_csv_writes_angles_with_the_promised_nine_decimals(tmp_path):
    """The README promises angles with 9 decimals (< 0.1 mm) and other numbers with 4: read back by
    Python's csv module, every latitude/longitude within 5e-10 degrees of what was written, every
    height within 5e-5 m (cutting the angles to 6 decimals, ~0.1 m, used to pass the writer's own
    tests)."""
    import csv

    from eoloc.io.writers import write_layer

    rng = np.random.default_rng(9)
    lat, lon, h = rng.uniform(-89, 89, 500), rng.uniform(-180, 180, 500), rng.uniform(-400, 9000, 500)
    rows = [{"target_id": str(i), "lat_deg": float(a), "lon_deg": float(b), "h_m": float(c), "status": "OK"}
            for i, (a, b, c) in enumerate(zip(lat, lon, h, strict=True))]
    (path,) = write_layer(tmp_path, "fixes", rows, ["csv"])
    back = list(csv.DictReader(path.open()))
    assert np.max(np.abs(np.array([float(r["lat_deg"]) for r in back]) - lat)) < 5e-10
    assert np.max(np.abs(np.array([float(r["lon_deg"]) for r in back]) - lon)) < 5e-10
    assert np.max(np.abs(np.array([float(r["h_m"]) for r in back]) - h)) < 5e-5
