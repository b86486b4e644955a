#!/usr/bin/env python3
"""Writes the textured-plane fixture (albedo textures), so its origin is plain.

fixtures/scenes/textured/checker.png: 64 x 64 sRGB texels, four 32 x 32
quadrants of known 8-bit colours (QUADRANTS below; row 0 is the image's top).
fixtures/scenes/textured/plane.gltf: a 1 m square in the y = 0 plane, facing
+y, with u along +x and v along +z (glTF's v = 0 is the image's top row), its
material's pbrMetallicRoughness.baseColorTexture the checker, factor 1.
fixtures/scenes/textured-plane.json: the plane under a point light, seen from
above. tests/render/texture_test.cpp checks albedo(u, v) E / pi at each
quadrant's centre, bench_render times it against the plane untextured.

Standard library only (scripts/fixture_gltf.py writes the PNG and the buffer). Rerun after changing
it: python3 scripts/make_textured_fixture.py
"""
import json
import pathlib

from fixture_gltf import png, quad_buffer

ROOT = pathlib.Path(__file__).resolve().parent.parent
OUT = ROOT / "fixtures" / "scenes" / "textured"
SIZE = 64
# (row half, column half) -> sRGB 8-bit colour: top-left, top-right, bottom-left, bottom-right.
QUADRANTS = {(0, 0): (230, 60, 40), (0, 1): (40, 180, 70), (1, 0): (50, 80, 220), (1, 1): (250, 250, 250)}


def checker_rows():
    half = SIZE // 2
    return [[QUADRANTS[(y // half, x // half)] for x in range(SIZE)] for y in range(SIZE)]


def plane_gltf(image_name):
    positions = [(-0.5, 0, -0.5), (0.5, 0, -0.5), (0.5, 0, 0.5), (-0.5, 0, 0.5)]
    uvs = [(x + 0.5, z + 0.5) for x, _, z in positions]
    indices = [0, 2, 1, 0, 3, 2]  # counter-clockwise seen from +y
    return {
        "asset": {"version": "2.0", "generator": "phos scripts/make_textured_fixture.py"},
        "scene": 0, "scenes": [{"nodes": [0]}], "nodes": [{"mesh": 0, "name": "plane"}],
        "meshes": [{"name": "plane", "primitives": [
            {"attributes": {"POSITION": 0, "TEXCOORD_0": 1}, "indices": 2, "material": 0}]}],
        "materials": [{"name": "checker", "pbrMetallicRoughness": {
            "baseColorFactor": [1, 1, 1, 1], "baseColorTexture": {"index": 0},
            "metallicFactor": 0, "roughnessFactor": 1}}],
        "textures": [{"source": 0}],
        "images": [{"uri": image_name}],
        **quad_buffer(positions, uvs, indices),
    }


def scene():
    return {
        "schema": "phos.scene/1", "name": "textured-plane",
        "description": "A 1 m plane of green glow paint printed with a 2 x 2 checker (glTF baseColorTexture) "
                       "under a white LED 1 m above.",
        "time": {"start_s": 0, "end_s": 1, "fps": 1},
        "camera": {"position": [0, 1.6, 0.001], "look_at": [0, 0, 0], "up": [0, 1, 0], "fov_deg": 40,
                   "width": 640, "height": 480, "exposure": 1},
        # Glow paint printed with the checker: its albedo from the texture
        # (the mesh's base colour wins over the phosphor's measured albedo),
        # charged by the lamp; the white LED reaches bands Table 8.1 has no
        # ke for, taken as zero in writing.
        "objects": [{"name": "plane", "mesh": "textured/plane.gltf", "phosphor": "../materials/green.json",
                     "unknown_ke": "zero"}],
        "lights": [{"name": "lamp", "type": "point", "position": [0, 1, 0], "intensity": 1,
                    "spectrum": {"type": "white_led"}}],
    }


def main():
    OUT.mkdir(parents=True, exist_ok=True)
    rows = [[v for pixel in row for v in pixel] for row in checker_rows()]
    (OUT / "checker.png").write_bytes(png(SIZE, SIZE, 3, rows, srgb=True))
    (OUT / "plane.gltf").write_text(json.dumps(plane_gltf("checker.png"), indent=1) + "\n")
    (OUT.parent / "textured-plane.json").write_text(json.dumps(scene(), indent=2) + "\n")


if __name__ == "__main__":
    main()
