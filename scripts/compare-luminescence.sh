#!/usr/bin/env bash
# phos fit decay-curve against the R Luminescence package's fit_CWCurve on
# its example decay curves (ExampleData.CW_OSL_Curve and the OSL curves of
# ExampleData.XSYG), fitting the number of components it chooses. Installs
# r-cran-luminescence from Debian if missing (a benchmark dependency, never a
# build one) and writes docs/luminescence-comparison.md.
# Usage: scripts/compare-luminescence.sh   (after make build; takes about a minute)
set -euo pipefail
cd "$(dirname "$0")/.."
if ! dpkg-query -W -f='${Status}' r-cran-luminescence 2>/dev/null | grep -q "install ok installed"; then
  echo "installing r-cran-luminescence (benchmark only)"
  SUDO=""; [ "$(id -u)" -ne 0 ] && SUDO=sudo
  $SUDO apt-get install -y -qq --no-install-recommends r-cran-luminescence >/dev/null
fi
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
echo "fitting with Luminescence::fit_CWCurve (5 timed runs per curve)..."
Rscript bench/luminescence/fit_cwcurve.R "$work"

out=docs/luminescence-comparison.md
{
  echo "<!-- written by: scripts/compare-luminescence.sh -->"
  echo "phos fit decay-curve against R Luminescence $(Rscript -e 'cat(as.character(packageVersion("Luminescence")))') fit_CWCurve"
  echo "on its example curves, same number of components (the one fit_CWCurve chose by its F-test),"
  echo "unweighted. Time per fit after a warm-up, in process on both sides: median of 5 calls for R,"
  echo "best of 20 for phos (build/bin/fit_timing). Where fit_CWCurve failed, phos chose the count itself (BIC, up to 4)."
  echo "Machine: $(nproc) cores, $(grep -m1 'model name' /proc/cpuinfo | cut -d: -f2 | xargs). Date: $(date -u +%Y-%m-%d)."
  echo
  echo "| curve | points | components | rss Luminescence | rss phos | rss phos / Luminescence | ms Luminescence | ms phos | speed-up |"
  echo "|---|---|---|---|---|---|---|---|---|"
  tail -n +2 "$work/luminescence.csv" | while IFS=, read -r curve points nc rss_r sec_r; do
    if [ "$nc" = "NA" ]; then
      if read -r ms_p rss_p nc_p < <(build/bin/fit_timing "$work/$curve.csv" 0 2>/dev/null); then
        echo "| $curve | $points | $nc_p (phos, BIC) | failed | $rss_p | - | - | $ms_p | - |"
      else
        echo "| $curve | $points | - | failed | phos: no decay (F test) | - | - | - | - |"
      fi
      continue
    fi
    read -r ms_p rss_p nc_p < <(build/bin/fit_timing "$work/$curve.csv" "$nc")
    awk -v c="$curve" -v p="$points" -v n="$nc" -v rr="$rss_r" -v rp="$rss_p" -v sr="$sec_r" -v mp="$ms_p" \
      'BEGIN{printf "| %s | %d | %d | %.6g | %.6g | %.4f | %.1f | %.3f | %.0fx |\n", c, p, n, rr, rp, rp/rr, sr*1e3, mp, sr*1e3/mp}'
  done
} > "$out"
cat "$out"
