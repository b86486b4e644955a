#!/bin/bash
# The trade of `phos render --exr-compression`: for each compression, the
# whole command's wall time (median of RUNS), the size of one EXR frame and
# its largest difference from zip's (idiff), on the Cornell fixture at
# 1920 x 1080, four frames, direct transport and the path tracer at 1 spp
# (whose noise compresses worst). Prints a Markdown table.
#
#   bench/exr_compression.sh [RUNS]     (default 3; uses build/bin/phos)
#
# Run from the repository's root, on a quiet machine: the runs of one row are
# back to back, the rows one after another.
set -euo pipefail
runs=${1:-3}
[[ "$runs" =~ ^[1-9][0-9]*$ ]] || { echo "exr_compression.sh: RUNS: expected a count from 1 up, not '$runs'" >&2; exit 2; }
phos=build/bin/phos
[ -x "$phos" ] || { echo "exr_compression.sh: $phos: not built (make build)" >&2; exit 2; }
command -v idiff >/dev/null || { echo "exr_compression.sh: idiff not found (openimageio-tools)" >&2; exit 2; }
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
scene=fixtures/scenes/cornell-phosphor.json

echo "| transport | compression | wall s (median of $runs) | MB per frame | max difference from zip (idiff) |"
echo "|---|---|---|---|---|"
for transport in direct path; do
  extra=(--transport "$transport")
  [ "$transport" = path ] && extra+=(--spp 1)
  for compression in zip none zips piz rle pxr24 dwaa dwab; do
    times=()
    for ((r = 0; r < runs; ++r)); do
      rm -rf "$work/$compression"
      start=$(date +%s.%N)
      "$phos" render "$scene" --out "$work/$compression" --times 20,40,60,80 --width 1920 --height 1080 \
        "${extra[@]}" --exr-compression "$compression" > /dev/null
      times+=("$(awk -v end="$(date +%s.%N)" -v start="$start" 'BEGIN {print end - start}')")
    done
    median=$(printf '%s\n' "${times[@]}" | sort -g | awk '{a[NR] = $1} END {print a[int((NR + 1) / 2)]}')
    bytes=$(stat -c %s "$work/$compression/frame-0000.exr")
    if [ "$compression" = zip ]; then
      difference="-"
      cp "$work/zip/frame-0000.exr" "$work/reference.exr"
    else
      difference=$(idiff -fail 1e30 -v "$work/reference.exr" "$work/$compression/frame-0000.exr" |
        awk '/Max error/ {print $4; found = 1} END {if (!found) print 0}')
    fi
    printf '| %s | %s | %.2f | %.1f | %s |\n' "$transport" "$compression" "$median" "$(awk -v bytes="$bytes" 'BEGIN {print bytes / 1000000}')" \
      "$difference"
  done
done
