#!/usr/bin/env python3
"""Draws scenarios/warehouse/map.pgm and map.yaml: a 60 m x 40 m warehouse at 0.05 m per pixel
(1200 x 800 pixels) in the ROS map_server format, with the standard Python library only.

The floor (x east, y north, origin at the lower-left corner (-30, -20)):
* outer walls 0.25 m thick;
* twelve shelving racks 1.2 m deep in six rows along x, two halves (x in [-20, -2] and
  [2, 20]) either side of a 4 m cross aisle, rows centred at y = -14, -10, ..., 6 (2.8 m aisles);
* three offices along the north wall (y in [12, 19.75]), 0.15 m walls, each with a 1.2 m door
  on the corridor side;
* a 6 m x 4 m machine enclosure in the north-east.

Pixels follow map_server's trinary convention: 0 (black) occupied, 254 (white) free. Run it
from the repository root: `python3 scripts/make-warehouse.py`; it rewrites both files
byte-for-byte identically.
"""

from pathlib import Path

RESOLUTION = 0.05
X0, Y0 = -30.0, -20.0
WIDTH, HEIGHT = 1200, 800
FREE, OCCUPIED = 254, 0

pixels = bytearray([FREE]) * (WIDTH * HEIGHT)


def fill(x_min, x_max, y_min, y_max):
    """Marks occupied every pixel whose centre lies in [x_min, x_max] x [y_min, y_max] (m)."""
    for row in range(HEIGHT):
        # Image row 0 is the top of the map (y = Y0 + HEIGHT * RESOLUTION).
        y = Y0 + (HEIGHT - row - 0.5) * RESOLUTION
        if not y_min <= y <= y_max:
            continue
        for col in range(WIDTH):
            x = X0 + (col + 0.5) * RESOLUTION
            if x_min <= x <= x_max:
                pixels[row * WIDTH + col] = OCCUPIED


# Outer walls.
T = 0.25
fill(-30, 30, -20, -20 + T)
fill(-30, 30, 20 - T, 20)
fill(-30, -30 + T, -20, 20)
fill(30 - T, 30, -20, 20)

# Shelving racks.
for centre in (-14, -10, -6, -2, 2, 6):
    for x_min, x_max in ((-20, -2), (2, 20)):
        fill(x_min, x_max, centre - 0.6, centre + 0.6)

# Offices along the north wall: a corridor-side wall at y = 12 with a door per office, and
# partitions at x = -22, -14, -6.
W = 0.15
doors = [(-27.0, -25.8), (-19.0, -17.8), (-11.0, -9.8)]
x = -30.0
for d0, d1 in doors:
    fill(x, d0, 12 - W / 2, 12 + W / 2)
    x = d1
fill(x, -6 + W / 2, 12 - W / 2, 12 + W / 2)
for px in (-22, -14, -6):
    fill(px - W / 2, px + W / 2, 12, 20)

# Machine enclosure.
fill(21, 27, 10, 14)

folder = Path(__file__).resolve().parent.parent / "scenarios" / "warehouse"
folder.mkdir(parents=True, exist_ok=True)
(folder / "map.pgm").write_bytes(b"P5\n%d %d\n255\n" % (WIDTH, HEIGHT) + bytes(pixels))
(folder / "map.yaml").write_text(
    "image: map.pgm\n"
    "mode: trinary\n"
    f"resolution: {RESOLUTION}\n"
    f"origin: [{X0}, {Y0}, 0.0]\n"
    "negate: 0\n"
    "occupied_thresh: 0.65\n"
    "free_thresh: 0.25\n"
)
print(f"wrote {folder / 'map.pgm'} ({WIDTH} x {HEIGHT}) and {folder / 'map.yaml'}")
