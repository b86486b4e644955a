#!/usr/bin/env python3
"""The gallery of make demo: every rendered fixture scene on one page, with
the description from its scene file, its contact sheet and its night-vision
frames (frame-NNNN-night.png, as a dark-adapted eye sees them).

    scripts/gallery.py OUT SHEET:SCENE:TRANSPORT ...

SHEET is the contact sheet OUT/SHEET.png and the frames' folder OUT/SHEET/,
SCENE the file fixtures/scenes/SCENE.json. Writes OUT/gallery.html
atomically (a temporary file, then a rename).
"""
import html
import json
import os
import sys
from pathlib import Path


def section(out, sheet, scene, transport):
    scene_file = Path("fixtures/scenes") / f"{scene}.json"
    description = json.loads(scene_file.read_text()).get("description", "")
    parts = [f"<h2>{html.escape(sheet)}</h2>",
             f"<p>{html.escape(description)}</p>",
             f"<p><code>{html.escape(str(scene_file))}</code>, --transport {html.escape(transport)}, "
             "--exposure auto (one exposure per sequence, from its frames after dark)</p>",
             f'<img src="{html.escape(sheet)}.png" alt="{html.escape(sheet)}: every frame">']
    night = sorted((out / sheet).glob("frame-*-night.png"))
    if night:
        parts.append("<p>Night vision: as a dark-adapted eye sees the frames (Thompson et al. 2002)</p><div>")
        for frame in night:
            src = f"{sheet}/{frame.name}"
            parts.append(f'<figure><img src="{html.escape(src)}" alt="{html.escape(src)}">'
                         f"<figcaption>{html.escape(frame.stem)}</figcaption></figure>")
        parts.append("</div>")
    return "\n".join(parts)


def main():
    if len(sys.argv) < 3:
        sys.exit("usage: gallery.py OUT SHEET:SCENE:TRANSPORT ...")
    out = Path(sys.argv[1])
    page = ['<!doctype html><meta charset="utf-8"><title>phos gallery</title>',
            "<style>body{background:#222;color:#ddd;font-family:sans-serif;margin:2em}img{max-width:100%}"
            "figure{display:inline-block;margin:0 8px 8px 0}figcaption{font-size:small}</style>",
            "<h1>phos: the fixture scenes (make demo)</h1>"]
    for entry in sys.argv[2:]:
        sheet, scene, transport = entry.split(":")
        page.append(section(out, sheet, scene, transport))
    temporary = out / "gallery.html.tmp"
    temporary.write_text("\n".join(page) + "\n")
    os.replace(temporary, out / "gallery.html")


if __name__ == "__main__":
    main()
