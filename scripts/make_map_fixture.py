#!/usr/bin/env python3
"""Writes the measured-tile fixture (docs/render.md, "Phosphor maps"): an object that
wears the `phos fit map` of a simulated sample whose material varies across
its surface, so the whole path is a script anyone can rerun.

fixtures/scenes/measured-tile/spot.json: the sample's centre, a faster and
brighter cousin of the green Table 8.1 preset: kr twice green's and Lambda
1.5 times (three times green's glow at a full charge, falling twice as
fast), the same ke (so a charge leaves it at a lower level than green).
fixtures/scenes/measured-tile/decay-map.exr: what the lab measured of it:
    phos capture decay --sim-material fixtures/materials/green.json
        --sim-inset fixtures/scenes/measured-tile/spot.json --sim-inset-radius 0.6
        --sim-size 64x64 --charge-s 1800 --duration-s 90 --out SESSION
    phos fit map SESSION --out MAP
(the simulated camera's default noise, seed 1: a rerun gives the same pixels; only the EXR
header's DateTime changes).
fixtures/scenes/measured-tile/tile.gltf: a 0.3 x 0.3 m tile in the z = 0.01
plane facing +z, 1.2 m up, u along +x, v down (glTF's v = 0 is the image's
top row, as the map's first row).
fixtures/scenes/measured-tile.json: the tile on a wall, its phosphor green
with the map over its UV map, lit by a desk lamp until 20 s; then a minute
of dark. The lamp's 20 s leave the spot at a lower level than the rest (its
faster decay, the same ke), so a second after light-off it glows 1.26 times
as bright as the rest, 5 s after half as bright. Rendered with the spot's
own material instead of the map, the spot's pixels agree within 1%.

Needs the built phos (make build). Rerun after changing it:
python3 scripts/make_map_fixture.py [path/to/phos]
"""
import json
import pathlib
import shutil
import subprocess
import sys
import tempfile

from fixture_gltf import wall_quad_buffer

ROOT = pathlib.Path(__file__).resolve().parent.parent
OUT = ROOT / "fixtures" / "scenes" / "measured-tile"
GREEN = ROOT / "fixtures" / "materials" / "green.json"
TILE, TILE_Y, TILE_Z = 0.3, 1.2, 0.01


def spot_material():
    material = json.loads(GREEN.read_text())
    material["name"] = "green spot (2x kr, 1.5x Lambda)"
    material["source"] = "scripts/make_map_fixture.py: the green preset, kr x2, Lambda x1.5, ke the same"
    for state in material["states"]:
        state["kr"] *= 2
        state["Lambda"] = [1.5 * value for value in state["Lambda"]]
        for key in ("kr_stderr", "ke_stderr"):
            state.pop(key, None)
    return material


def measure(phos, spot, work):
    session, fitted = work / "session", work / "map"
    subprocess.run([phos, "capture", "decay", "--sim-material", str(GREEN), "--sim-inset", str(spot),
                    "--sim-inset-radius", "0.6", "--sim-size", "64x64", "--charge-s", "1800", "--duration-s", "90",
                    "--out", str(session)], check=True, stdout=subprocess.DEVNULL)
    subprocess.run([phos, "fit", "map", str(session), "--out", str(fitted)], check=True)
    return fitted / "decay-map.exr"


def tile_gltf():
    return {
        "asset": {"version": "2.0", "generator": "phos scripts/make_map_fixture.py"},
        "scene": 0, "scenes": [{"nodes": [0]}],
        "nodes": [{"mesh": 0, "name": "tile"}],
        "meshes": [{"name": "tile", "primitives": [{"attributes": {"POSITION": 0, "TEXCOORD_0": 1}, "indices": 2}]}],
        **wall_quad_buffer(TILE, TILE, TILE_Y, TILE_Z),  # v down, as the map's rows
    }


def scene():
    return {
        "schema": "phos.scene/1",
        "name": "measured-tile",
        "description": ("A tile of green glow paint with a spot of a faster, brighter paint in its middle, rendered "
                        "from what the simulated lab measured of it: the phosphor is the green Table 8.1 preset, "
                        "its rates and levels per texel from phos fit map. A desk lamp charges it until 20 s; a "
                        "second later the spot glows a quarter brighter than the rest, 5 s later half as bright, "
                        "and it is gone long before the rest. Made by scripts/make_map_fixture.py."),
        "time": {"start_s": 0, "end_s": 80, "fps": 1},
        "camera": {"position": [0.0, 1.25, 0.7], "look_at": [0.0, 1.2, 0.0], "fov_deg": 40,
                   "width": 240, "height": 200, "exposure": "auto"},
        "objects": [
            {"name": "wall", "shape": {"type": "box", "size": [2, 3, 0.1]},
             "transform": {"translate": [0, 1.5, -0.05]}, "albedo": 0.6},
            {"name": "tile", "mesh": "measured-tile/tile.gltf", "albedo": 0.8, "phosphor": "../materials/green.json",
             "phosphor_map": "measured-tile/decay-map.exr", "unknown_ke": "zero"},
        ],
        "lights": [
            {"name": "desk lamp", "type": "point", "position": [0.3, 1.6, 0.5], "intensity": 0.5,
             "spectrum": {"type": "white_led"}, "schedule": [{"t_s": 0, "level": 1}, {"t_s": 20, "level": 0}]},
        ],
    }


def main():
    phos = sys.argv[1] if len(sys.argv) > 1 else str(ROOT / "build" / "bin" / "phos")
    OUT.mkdir(parents=True, exist_ok=True)
    spot = OUT / "spot.json"
    spot.write_text(json.dumps(spot_material(), indent=2) + "\n")
    with tempfile.TemporaryDirectory() as work:
        shutil.copyfile(measure(phos, spot, pathlib.Path(work)), OUT / "decay-map.exr")
    (OUT / "tile.gltf").write_text(json.dumps(tile_gltf(), indent=1) + "\n")
    (OUT.parent / "measured-tile.json").write_text(json.dumps(scene(), indent=2) + "\n")


if __name__ == "__main__":
    main()
