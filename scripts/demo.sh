#!/usr/bin/env bash
# The main job: simulate the Table 8.1 presets under a charge-then-dark
# schedule, capture a decay in the simulated lab, and render scenes where the
# materials charge under a lamp and glow after it goes off; everything goes
# to results/.
set -euo pipefail
cd "$(dirname "$0")/.."
PHOS=build/bin/phos
OUT=results
mkdir -p "$OUT"

# Light in bands 1-3 (400-512.5 nm, UV-blue): the only bands where Table 8.1
# measured ke. Charge 60 s, then 300 s of darkness, a sample every 0.5 s.
LIGHT=1,1,1,0,0,0,0,0
charged=()
for name in blue green orange pink purple red white yellow; do
  "$PHOS" simulate --material "fixtures/materials/$name.json" --charge-s 60 --irradiance "$LIGHT" \
    --decay-s 300 --dt 0.5 --out "$OUT/$name.csv" --plot "$OUT/$name.svg"
  charged+=("$OUT/$name.csv")
done
# bottle, gloves, stickers: ke was never measured, so phos refuses to charge
# them; they decay from saturation (r0 = 1).
decay_only=()
for name in bottle gloves stickers; do
  "$PHOS" simulate --material "fixtures/materials/$name.json" --r0 1 --decay-s 300 --dt 0.5 \
    --out "$OUT/$name.csv" --plot "$OUT/$name.svg"
  decay_only+=("$OUT/$name.csv")
done
"$PHOS" plot "${charged[@]}" --log-y --out "$OUT/charged.svg" \
  --title "Table 8.1 presets: 60 s under UV-blue light (E = 1 in bands 1-3), then dark"
"$PHOS" plot "${decay_only[@]}" --log-y --out "$OUT/decay-only.svg" \
  --title "Presets without measured ke: decay from saturation (r0 = 1)"

# The lab, simulated: the four protocols of Sec. 8.4 on the orange preset
# (LVF calibration, spectrum, a decay after a 90-minute charge under the
# 405 nm LED, excitation under three LEDs); 17.5 hours of bench time on the
# virtual clock take a second. Previews: a contact sheet of the decay frames
# and the measured curves.
rm -rf "$OUT/capture-orange"
"$PHOS" capture all --device sim --sim-material fixtures/materials/orange.json --out "$OUT/capture-orange"
# ... and fit it back into a material (Sec. 8.4.2-8.4.6), with a report, and
# say how close it came to the preset the simulated sample was made of.
mkdir -p "$OUT/fitted"
"$PHOS" fit session "$OUT/capture-orange" --out "$OUT/fitted/orange.json" --report "$OUT/fitted/orange-report.html" \
  --compare fixtures/materials/orange.json

# Render the still life (Fig. 8.1): lamp on until 20 s, then a minute of
# darkness. The orange ball wears the material just fitted from the capture
# (results/fitted/orange.json).
# Every scene: one exposure per sequence that shows the glow (chosen from the
# frames after dark, docs/render.md "Exposure") and the night-vision frames.
VIEWS="--exposure auto --night-vision 0.05"
material_args=()
if [ -f "$OUT/fitted/orange.json" ]; then
  material_args=(--material "orange ball=$OUT/fitted/orange.json")
fi
rm -rf "$OUT/still-life" "$OUT/cornell" "$OUT/light-trail"
"$PHOS" render fixtures/scenes/still-life.json --out "$OUT/still-life" --times 0,10,19,21,30,50,80 \
  --contact-sheet "$OUT/still-life.png" $VIEWS "${material_args[@]}"
# The Cornell box of Fig. 8.15, path traced 10 s after the LED went off: the
# glowing walls light the white blocks.
"$PHOS" render fixtures/scenes/cornell-phosphor.json --out "$OUT/cornell" --times 20,31,40,90 \
  --transport path --contact-sheet "$OUT/cornell.png" $VIEWS
# The same box 10 s after lights-out with one bounce through deep screen
# space instead of paths (docs/render.md compares the two).
rm -rf "$OUT/cornell-dss"
"$PHOS" render fixtures/scenes/cornell-phosphor.json --out "$OUT/cornell-dss" --times 40 --transport dss \
  --contact-sheet "$OUT/cornell-dss.png" $VIEWS
# A moving 405 nm LED writes a fading trail into a painted floor.
"$PHOS" render fixtures/scenes/light-trail.json --out "$OUT/light-trail" --times 1,3,5,7,9,10,12,15 \
  --contact-sheet "$OUT/light-trail.png" $VIEWS
# Phosphorescent media: a dust cloud swept by laser sheets (Fig. 8.17) and a
# glowing liquid charged from above (Fig. 8.18), one state per voxel.
rm -rf "$OUT/dust-sheets" "$OUT/glowing-liquid"
"$PHOS" render fixtures/scenes/dust-sheets.json --out "$OUT/dust-sheets" --times 1.5,3,3.55,5,8 \
  --contact-sheet "$OUT/dust-sheets.png" $VIEWS
"$PHOS" render fixtures/scenes/glowing-liquid.json --out "$OUT/glowing-liquid" --times 10,20,40,80 \
  --contact-sheet "$OUT/glowing-liquid.png" $VIEWS
# Translucent wax through deep screen space: light bleeds into the post's
# shadow and through the slab's sides (dipole diffusion).
rm -rf "$OUT/translucent-shadow"
"$PHOS" render fixtures/scenes/translucent-shadow.json --out "$OUT/translucent-shadow" --times 2,8 --transport dss \
  --contact-sheet "$OUT/translucent-shadow.png" $VIEWS
# A sign charged by the sky through the afternoon glows at dusk; the porch
# roof's shadow of the sky is directional occlusion through deep space.
rm -rf "$OUT/dusk-sign"
"$PHOS" render fixtures/scenes/dusk-sign.json --out "$OUT/dusk-sign" --times 30,45,55,62,90 --transport dss \
  --contact-sheet "$OUT/dusk-sign.png" $VIEWS
# An EXIT sign whose letters only are glow paint (a mask over a textured
# board, from a glTF file with its own spot light), under a ceiling panel
# (an area light) until 20 s; fixtures/scenes/glow-sign.json is made by
# scripts/make_sign_fixture.py.
rm -rf "$OUT/glow-sign"
"$PHOS" render fixtures/scenes/glow-sign.json --out "$OUT/glow-sign" --times 10,21,25,35,50 \
  --contact-sheet "$OUT/glow-sign.png" $VIEWS
# A tile wearing what the simulated lab measured of it (phos fit map): a
# spot of a faster, brighter paint in green glow paint, charged by a desk
# lamp until 20 s; fixtures/scenes/measured-tile.json is made by
# scripts/make_map_fixture.py.
rm -rf "$OUT/measured-tile"
"$PHOS" render fixtures/scenes/measured-tile.json --out "$OUT/measured-tile" --times 10,21,25,30,40 \
  --contact-sheet "$OUT/measured-tile.png" $VIEWS

# The gallery: every fixture scene on one page, with its description, its
# contact sheet and its night-vision frames.
python3 scripts/gallery.py "$OUT" still-life:still-life:direct cornell:cornell-phosphor:path \
  cornell-dss:cornell-phosphor:dss light-trail:light-trail:direct dust-sheets:dust-sheets:direct \
  glowing-liquid:glowing-liquid:direct translucent-shadow:translucent-shadow:dss dusk-sign:dusk-sign:dss \
  glow-sign:glow-sign:direct measured-tile:measured-tile:direct

echo "phos demo: simulated 11 Table 8.1 presets (60 s charge, 300 s dark, exact integrator)"
echo "  curves (CSV: t,r_1,L_1..L_8):  $OUT/<material>.csv"
echo "  plots (SVG):                   $OUT/charged.svg, $OUT/decay-only.svg, $OUT/<material>.svg"
echo "  a captured sample (4 protocols): $OUT/capture-orange/{lvf-calibration,spectrum,decay,excitation}"
echo "    what it captured: $OUT/capture-orange/decay-frames.png (contact sheet), decay-curve.svg, excitation-curves.svg"
echo "  the material fitted from it:  $OUT/fitted/orange.json, report $OUT/fitted/orange-report.html"
echo "  rendered scenes (contact sheets): $OUT/still-life.png, $OUT/cornell.png, $OUT/cornell-dss.png, $OUT/light-trail.png,"
echo "    $OUT/dust-sheets.png, $OUT/glowing-liquid.png, $OUT/translucent-shadow.png, $OUT/dusk-sign.png,"
echo "    $OUT/glow-sign.png, $OUT/measured-tile.png; all on one page: $OUT/gallery.html"
echo "    frames (EXR data, PNG, night-vision PNG): $OUT/still-life/, $OUT/cornell/, $OUT/light-trail/, ..."
