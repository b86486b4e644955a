#!/usr/bin/env python3
"""Writes the glow-sign fixture (a textured sign, glow paint, lights), so its origin is plain.

fixtures/scenes/glow-sign/board.png: the sign's base colour, 128 x 128 sRGB:
a dark green board with a cream border (glTF baseColorTexture).
fixtures/scenes/glow-sign/mask.png: the glow paint, 256 x 256 grey: the
letters EXIT and an arrow in a 5 x 7 pixel font, each font pixel 6 mask
pixels wide and 14 high (the plate is 2.4 times wider than high, and the
mask spans its UV square), edges anti-aliased by 4 x 4 supersampling so
that some texels are partly painted.
fixtures/scenes/glow-sign/sign.gltf: a 0.6 x 0.25 m plate in the z = 0.01
plane facing +z, 1.5 m up, u along +x, v down (glTF's v = 0 is the image's
top row); its material's baseColorTexture is the board; and a
KHR_lights_punctual spot (a gooseneck lamp) 0.45 m in front of it and
0.35 m above, its node turned to aim at the plate.
fixtures/scenes/glow-sign.json: the plate on a wall (phosphor: the green
Table 8.1 preset, painted where the mask says), a ceiling panel (a quad
area light) and the glTF's spot, both on until 20 s; then a minute of dark.

Standard library only (scripts/fixture_gltf.py writes the PNGs and the buffer). Rerun after changing
it: python3 scripts/make_sign_fixture.py
"""
import json
import math
import pathlib

from fixture_gltf import png, wall_quad_buffer

ROOT = pathlib.Path(__file__).resolve().parent.parent
OUT = ROOT / "fixtures" / "scenes" / "glow-sign"
PLATE_W, PLATE_H, PLATE_Y, PLATE_Z = 0.6, 0.25, 1.5, 0.01

FONT = {  # 5 x 7, rows from the top
    "E": ["#####", "#....", "#....", "####.", "#....", "#....", "#####"],
    "X": ["#...#", "#...#", ".#.#.", "..#..", ".#.#.", "#...#", "#...#"],
    "I": ["#####", "..#..", "..#..", "..#..", "..#..", "..#..", "#####"],
    "T": ["#####", "..#..", "..#..", "..#..", "..#..", "..#..", "..#.."],
    ">": ["#....", ".#...", "..#..", "...#.", "..#..", ".#...", "#...."],
}


def board_rows(size=128, border=6):
    rows = []
    for y in range(size):
        row = []
        for x in range(size):
            edge = min(x, y, size - 1 - x, size - 1 - y) < border
            grain = int(6 * math.sin(0.9 * x + 0.3 * y) * math.sin(0.21 * y))  # a painted board's streaks
            row += [235, 225, 200] if edge else [40 + grain, 62 + grain, 52 + grain]
        rows.append(row)
    return rows


def mask_rows(size=256, cell_w=6, cell_h=14, text="EXIT >"):
    columns = 6 * len(text) - 1
    x0 = (size - columns * cell_w) // 2
    y0 = (size - 7 * cell_h) // 2

    def painted(px, py):  # px, py in mask pixels (float)
        col, row = int((px - x0) // cell_w), int((py - y0) // cell_h)
        if not (0 <= row < 7 and 0 <= col < columns) or col % 6 == 5:
            return 0.0
        glyph = FONT.get(text[col // 6])
        return 1.0 if glyph and glyph[row][col % 6] == "#" else 0.0

    rows = []
    for y in range(size):
        row = []
        for x in range(size):
            cover = sum(painted(x + (i + 0.5) / 4, y + (j + 0.5) / 4) for i in range(4) for j in range(4)) / 16
            row.append(round(255 * cover))
        rows.append(row)
    return rows


def sign_gltf():
    y1 = PLATE_Y + PLATE_H / 2
    # The lamp at (0, y1 + 0.35, 0.45), aimed at the plate's centre: a node's
    # light shines down its -z axis, so rotate -z onto the aim (about x).
    lamp = (0.0, y1 + 0.35, 0.45)
    aim = (0.0, PLATE_Y - lamp[1], PLATE_Z - lamp[2])
    pitch = math.atan2(-aim[1], -aim[2])  # rotation about x taking -z to the aim
    rotation = [-math.sin(pitch / 2), 0.0, 0.0, math.cos(pitch / 2)]
    return {
        "asset": {"version": "2.0", "generator": "phos scripts/make_sign_fixture.py"},
        "extensionsUsed": ["KHR_lights_punctual"],
        "extensions": {"KHR_lights_punctual": {"lights": [
            {"name": "gooseneck lamp", "type": "spot", "intensity": 200, "color": [1, 1, 1],
             "spot": {"innerConeAngle": 0.35, "outerConeAngle": 0.6}}]}},
        "scene": 0, "scenes": [{"nodes": [0, 1]}],
        "nodes": [{"mesh": 0, "name": "plate"},
                  {"name": "lamp", "translation": list(lamp), "rotation": rotation,
                   "extensions": {"KHR_lights_punctual": {"light": 0}}}],
        "meshes": [{"name": "plate", "primitives": [
            {"attributes": {"POSITION": 0, "TEXCOORD_0": 1}, "indices": 2, "material": 0}]}],
        "materials": [{"name": "board", "pbrMetallicRoughness": {
            "baseColorFactor": [1, 1, 1, 1], "baseColorTexture": {"index": 0},
            "metallicFactor": 0, "roughnessFactor": 0.8}}],
        "textures": [{"source": 0}],
        "images": [{"uri": "board.png"}],
        **wall_quad_buffer(PLATE_W, PLATE_H, PLATE_Y, PLATE_Z),
    }


def scene():
    off = [{"t_s": 0, "level": 1}, {"t_s": 20, "level": 0}]
    return {
        "schema": "phos.scene/1",
        "name": "glow-sign",
        "description": ("An EXIT sign painted with glow paint (the green Table 8.1 preset) on a textured board: "
                        "only the letters carry the phosphor (a mask over the plate's UV map). A ceiling panel "
                        "(a quad area light) and a gooseneck spot from the glTF file (KHR_lights_punctual) light it "
                        "until 20 s; then the letters glow in the dark. Made by scripts/make_sign_fixture.py."),
        "time": {"start_s": 0, "end_s": 80, "fps": 1},
        "texel_size_m": 0.01,
        "camera": {"position": [0.35, 1.35, 1.3], "look_at": [0.0, 1.5, 0.0], "fov_deg": 40,
                   "width": 320, "height": 200, "exposure": "auto"},
        "render": {"spp": 32, "max_depth": 4},
        "objects": [
            {"name": "floor", "shape": {"type": "quad", "size": [4, 4]}, "albedo": 0.3},
            {"name": "wall", "shape": {"type": "box", "size": [4, 3, 0.1]},
             "transform": {"translate": [0, 1.5, -0.05]}, "albedo": 0.7},
            {"name": "exit sign", "mesh": "glow-sign/sign.gltf", "phosphor": "../materials/green.json",
             "phosphor_mask": "glow-sign/mask.png", "uv_resolution": 256, "unknown_ke": "zero"},
        ],
        "lights": [
            {"name": "ceiling panel", "type": "quad", "position": [0, 2.9, 0.9], "normal": [0, -1, 0],
             "size_m": [0.8, 0.5], "samples": 16, "intensity": 20, "spectrum": {"type": "white_led"},
             "schedule": off},
            {"type": "gltf", "file": "glow-sign/sign.gltf", "intensity_scale": 0.01,
             "spectrum": {"type": "white_led"}, "schedule": off},
        ],
    }


def main():
    OUT.mkdir(parents=True, exist_ok=True)
    (OUT / "board.png").write_bytes(png(128, 128, 3, board_rows(), srgb=True))
    (OUT / "mask.png").write_bytes(png(256, 256, 1, mask_rows()))
    (OUT / "sign.gltf").write_text(json.dumps(sign_gltf(), indent=1) + "\n")
    (OUT.parent / "glow-sign.json").write_text(json.dumps(scene(), indent=2) + "\n")


if __name__ == "__main__":
    main()
