#!/usr/bin/env python3
"""Writes data/lights/sponza_100.json: 100 point lights in Dabrovic Sponza (issue 20's
many-light case) — a 10 x 5 grid of lamps along the ground floor's arcades (0.3 m above the
floor) and 50 over the upper galleries (6.8 m), warm colours, intensities over two decades,
from a fixed seed so the file is the same on every run.

    /usr/bin/python3 scripts/lights/sponza_100.py [OUT]
"""
import json
import random
import sys

rng = random.Random(2026)
lights = []
for level, y in (("ground", 0.3), ("gallery", 6.8)):
    for i in range(10):
        for j in range(5):
            x = -13.5 + 3.0 * i + rng.uniform(-0.3, 0.3)
            z = -5.0 + 2.5 * j + rng.uniform(-0.3, 0.3)
            lights.append({
                "name": f"{level}_{i}_{j}", "type": "point", "position": [round(x, 3), y, round(z, 3)],
                "color": [1.0, round(rng.uniform(0.6, 0.85), 3), round(rng.uniform(0.3, 0.55), 3)],
                "intensity": round(0.05 * 10 ** rng.uniform(0, 2), 4),
            })
out = sys.argv[1] if len(sys.argv) > 1 else "data/lights/sponza_100.json"
with open(out, "w") as f:
    json.dump({"scene": "dabrovic_sponza/sponza.obj", "lights": lights}, f, indent=1)
print(f"wrote {len(lights)} lights to {out}")
