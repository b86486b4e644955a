#!/usr/bin/env bash
# phos against the R Luminescence package's fit_CWCurve on its example CW-OSL
# curves (62: ExampleData.CW_OSL_Curve, the 14 OSL curves of ExampleData.XSYG,
# and the Ln and Tn curves of the 24 aliquots of ExampleData.BINfileData but
# aliquot 1's Ln, which is CW_OSL_Curve),
# both choosing the number of components (1..3) and both timed in process in
# this one run; then phos's residual at fit_CWCurve's count, and one
# `phos fit decay-curve` call on every file. Installs r-cran-luminescence from
# Debian if missing (a benchmark dependency, never a build one) and writes
# docs/luminescence-comparison.md.
# Usage: scripts/compare-luminescence.sh   (after make build; about 2 minutes;
#        on a shared machine run it under flock /tmp/phos-build.lock)
set -euo pipefail
cd "$(dirname "$0")/.."
if ! dpkg-query -W -f='${Status}' r-cran-luminescence 2>/dev/null | grep -q "install ok installed"; then
  echo "installing r-cran-luminescence (benchmark only)"
  SUDO=""; [ "$(id -u)" -ne 0 ] && SUDO=sudo
  $SUDO apt-get install -y -qq --no-install-recommends r-cran-luminescence >/dev/null
fi
for tool in build/bin/fit_timing build/bin/phos; do
  [ -x "$tool" ] || { echo "compare-luminescence.sh: $tool is missing: build the Release tree first (make build)" >&2; exit 2; }
done
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
# The residual comparison's tolerance: phos's RSS counts as at most R's when
# it is below R's times (1 + this); both converge to about 1e-10 relative.
tolerance=1e-6

echo "fitting with Luminescence::fit_CWCurve (n.components.max = 3; 5 timed runs per curve)..."
Rscript bench/luminescence/fit_cwcurve.R "$work"
files=()
while IFS=, read -r curve _; do files+=("$work/$curve.csv"); done < <(tail -n +2 "$work/luminescence.csv")

echo "timing phos in process, the count chosen by BIC over 1..3 (build/bin/fit_timing 0)..."
build/bin/fit_timing 0 "${files[@]}" >"$work/bic.txt" 2>/dev/null || true
echo "phos at fit_CWCurve's count (build/bin/fit_timing N)..."
: >"$work/fixed.txt"
for nc in 1 2 3; do
  chosen=()
  while IFS=, read -r curve _ n _; do [ "$n" = "$nc" ] && chosen+=("$work/$curve.csv"); done < <(tail -n +2 "$work/luminescence.csv")
  [ ${#chosen[@]} -gt 0 ] && build/bin/fit_timing "$nc" "${chosen[@]}" >>"$work/fixed.txt" 2>/dev/null
done
echo "one phos fit decay-curve call on all ${#files[@]} files (median of 5 runs)..."
for run in 1 2 3 4 5; do
  start=$EPOCHREALTIME
  build/bin/phos fit decay-curve "${files[@]}" >/dev/null 2>&1 || true  # the noise curve is refused (exit 2)
  end=$EPOCHREALTIME
  awk -v s="$start" -v e="$end" 'BEGIN {printf "%.3f\n", (e - s) * 1000}'
done | sort -g | sed -n 3p >"$work/cli_ms"

# One line per curve: curve points nc_R rss_R ms_R nc_phos_bic ms_phos_bic rss_phos_at_R_count
tail -n +2 "$work/luminescence.csv" | tr ',' ' ' | while read -r curve points nc_r rss_r sec_r; do
  read -r _ ms_bic _ nc_bic _ < <(grep "^$work/$curve.csv " "$work/bic.txt" || echo "x - - - -")
  read -r _ _ rss_fixed _ _ < <(grep "^$work/$curve.csv " "$work/fixed.txt" || echo "x - - - -")
  echo "$curve $points $nc_r $rss_r $sec_r $nc_bic $ms_bic $rss_fixed"
done >"$work/rows.txt"

out=docs/luminescence-comparison.md
awk -v tol="$tolerance" -v cli_ms="$(cat "$work/cli_ms")" -v n_files="${#files[@]}" \
    -v version="$(Rscript -e 'cat(as.character(packageVersion("Luminescence")))')" \
    -v machine="$(nproc) cores, $(grep -m1 'model name' /proc/cpuinfo | cut -d: -f2 | xargs)" \
    -v date="$(date -u +%Y-%m-%d)" -v load="$(cut -d' ' -f1-3 /proc/loadavg)" '
function median(a, n,   i, j, t) {
  for (i = 2; i <= n; ++i) for (j = i; j > 1 && a[j - 1] > a[j]; --j) { t = a[j]; a[j] = a[j - 1]; a[j - 1] = t }
  return n % 2 ? a[(n + 1) / 2] : (a[n / 2] + a[n / 2 + 1]) / 2
}
{
  rows[NR] = $0; curve = $1; ms_r = $5 * 1e3
  if ($3 != "NA" && $7 != "-") { ++timed; speed[timed] = ms_r / $7; r_ms[timed] = ms_r; p_ms[timed] = $7
                                 if (timed == 1 || ms_r / $7 < worst) { worst = ms_r / $7; worst_curve = curve } }
  if ($3 != "NA") { ++both; if ($8 != "-" && $8 <= $4 * (1 + tol)) ++not_worse }
  if ($3 == "NA") ++r_failed
  if ($7 == "-") ++p_refused
  if ($3 != "NA" && $6 != "-" && $3 == $6) ++same_count
  if ($3 != "NA") { ++r_sum_n; r_sum += ms_r }
}
END {
  print "<!-- written by: scripts/compare-luminescence.sh -->"
  printf "# phos against R Luminescence %s fit_CWCurve\n\n", version
  printf "Written by `scripts/compare-luminescence.sh` on %s (%s; load %s at the end).\n", date, machine, load
  printf "%d example CW-OSL curves of the R package: ExampleData.CW_OSL_Curve, the 14 OSL curves of\n", NR
  print "ExampleData.XSYG, and the natural (Ln) and test-dose (Tn) OSL curves of the 24 aliquots of"
  print "ExampleData.BINfileData (CWOSL.SAR.Data) but aliquot 1 Ln, which is CW_OSL_Curve itself."
  print "Unweighted, no background, on both sides."
  print ""
  print "- **Model choice, in process.** fit_CWCurve chooses the count by its F-test (n.components.max = 3),"
  print "  phos by BIC over 1..3 (build/bin/fit_timing 0). Time per fit after a warm-up: median of 5 calls"
  print "  for R (system.time), median of 21 for phos (steady_clock)."
  printf "  Over the %d curves both fitted, phos was a **median %.0fx** faster (R %.1f ms, phos %.3f ms per curve,\n", timed, median(speed, timed), median(r_ms, timed), median(p_ms, timed)
  printf "  medians), **%.0fx at worst** (%s).\n", worst, worst_curve
  printf "- **Residual at the same count.** phos fitted the count fit_CWCurve chose (build/bin/fit_timing N);\n"
  printf "  its RSS was at most that of R (relative tolerance %g) on **%d of %d** curves (%.0f%%).\n", tol, not_worse, both, 100 * not_worse / both
  printf "  Their counts agreed on %d of %d.\n", same_count, both
  printf "- **Command line, many files.** One `phos fit decay-curve FILE...` call on all %d files (the count by\n", n_files
  printf "  BIC, table on stdout): %.1f ms wall time (median of 5), **%.2f ms per curve**, against a mean of\n", cli_ms, cli_ms / n_files
  printf "  %.1f ms per curve for fit_CWCurve in process.\n", r_sum / r_sum_n
  printf "- fit_CWCurve failed on %d curve(s); phos refused %d as having no decay (F test against a constant).\n", r_failed, p_refused
  print ""
  print "| curve | points | nc R (F-test) | nc phos (BIC) | rss R | rss phos at the nc of R | phos / R | ms R | ms phos (BIC) | speed-up |"
  print "|---|---|---|---|---|---|---|---|---|---|"
  for (i = 1; i <= NR; ++i) {
    split(rows[i], f, " ")
    ratio = (f[3] != "NA" && f[8] != "-") ? sprintf("%.4f", f[8] / f[4]) : "-"
    sp = (f[3] != "NA" && f[7] != "-") ? sprintf("%.0fx", f[5] * 1e3 / f[7]) : "-"
    printf "| %s | %d | %s | %s | %s | %s | %s | %.0f | %s | %s |\n", f[1], f[2], f[3] == "NA" ? "failed" : f[3],
           f[6] == "-" ? "no decay" : f[6], f[4] == "NA" ? "-" : sprintf("%.6g", f[4]),
           f[8] == "-" ? "-" : sprintf("%.6g", f[8]), ratio, f[5] * 1e3, f[7], sp
  }
}' "$work/rows.txt" >"$out"
cat "$out"
