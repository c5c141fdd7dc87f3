#!/usr/bin/env bash
# What --fast-shrink costs in accuracy and saves in time (issue 45), on a JPEG-tiled slide
# (bench/lib.sh's make_slide: libvips 8.18, 256-texel RGB JPEG tiles at Q=90, BigTIFF).
#
# For each filter (box, and the default linear-premultiplied, which is `linear` on these opaque
# images) three Deep Zoom pyramids of 256-texel tiles with no overlap are made:
#   reference  the exact pyramid in PNG tiles (lossless): every LOD the filter's exact mean
#   exact      the exact pyramid as a user makes it: LOD 0 the stored tiles, copied; the
#              rest JPEG Q85 (the default)
#   fast       the same with --fast-shrink: LOD 1 from the stored tiles decoded at half size
# and every LOD from 1 up of `exact` and `fast` is compared with the reference's (PSNR over the
# three samples, and the largest difference, in code values), so that the JPEG encoding both
# share is in both rows and the difference between them is what --fast-shrink costs. Then the
# wall, CPU and peak memory of `exact` and `fast`, to Deep Zoom and to a pack (--border 0),
# RUNS times each, alternating, medians.
#
# Usage, from the repository root:  bench/fast-shrink.sh
#   SIZE (default 16384x16384), RUNS (default 5), FILTERS (default "box linear-premultiplied"),
#   VORTEX_PYVIPS (a Python with pyvips; else bench/lib.sh installs one), DOC (default
#   docs/accuracy.md: the tables go between its fast-shrink markers). Run it on a quiet machine.
set -euo pipefail
DOC=${DOC:-$PWD/docs/accuracy.md}
source bench/lib.sh
bench_setup
pyvips_setup
[ -n "$PY" ] || { echo "error: no Python with pyvips to make the slide and compare the levels" >&2; exit 1; }
VT=$WORK/bin/vortex-tiler
SIZE=${SIZE:-16384x16384}
RUNS=${RUNS:-5}
FILTERS=${FILTERS:-box linear-premultiplied}
OUT=$WORK/fast-shrink
mkdir -p "$OUT"
SLIDE=$WORK/slide-$SIZE.tif
make_slide "${SIZE%x*}" "${SIZE#*x}" "$SLIDE"
DZ=(--layout dzi --overlap 0 --tile-size 256 -q)

# levels DIR_A DIR_B: per LOD from 1 up, "lod psnr max" of Deep Zoom pyramid A against B (the
# reference), and a last line "all psnr max" over every texel of LODs 1 and up.
levels() {
  "$PY" - "$1" "$2" <<'PY'
import glob, math, os, sys
import pyvips
a, b = (glob.glob(os.path.join(d, "*_files"))[0] for d in sys.argv[1:3])
levels = sorted((int(n) for n in os.listdir(b)), reverse=True)
sq, count, worst = 0.0, 0, 0.0
for lod, level in enumerate(levels):
    if lod == 0:
        continue
    def image(root):
        names = glob.glob(os.path.join(root, str(level), "*.*"))
        cols = 1 + max(int(os.path.basename(n).split("_")[0]) for n in names)
        rows = 1 + max(int(os.path.basename(n).split("_")[1].split(".")[0]) for n in names)
        ext = os.path.splitext(names[0])[1]
        tiles = [pyvips.Image.new_from_file(os.path.join(root, str(level), f"{c}_{r}{ext}"))
                 for r in range(rows) for c in range(cols)]
        return pyvips.Image.arrayjoin(tiles, across=cols).extract_band(0, n=3).cast("float")
    x, y = image(a), image(b)
    d = x - y
    mse, big = (d * d).avg(), abs(d).max()
    n = x.width * x.height * 3
    sq, count, worst = sq + mse * n, count + n, max(worst, big)
    print(lod, f"{10 * math.log10(255 ** 2 / mse):.2f}" if mse else "exact", f"{big:.0f}")
print("all", f"{10 * math.log10(255 ** 2 / (sq / count)):.2f}", f"{worst:.0f}")
PY
}

{
  echo "Measured by \`bench/fast-shrink.sh\` on $(date -u +%Y-%m-%d) with $REV, on a $SIZE slide (libvips 8.18's JPEG tiles, 256 texels, RGB at Q90): Deep Zoom pyramids of 256-texel tiles, no overlap, JPEG Q85 where not copied. PSNR in dB / largest difference in code values, against the exact pyramid of the same filter in lossless tiles."
  echo
  for filter in $FILTERS; do
    log "accuracy, --filter $filter"
    for run in reference exact fast; do
      rm -rf "$OUT/$run"
      case $run in
        reference) extra=(--codec png --png-compression fast) ;;
        exact) extra=() ;;
        fast) extra=(--fast-shrink) ;;
      esac
      "$VT" split "$SLIDE" -o "$OUT/$run" "${DZ[@]}" --filter "$filter" "${extra[@]}"
    done
    levels "$OUT/exact" "$OUT/reference" >"$OUT/exact.tsv"
    levels "$OUT/fast" "$OUT/reference" >"$OUT/fast.tsv"
    header="| \`--filter $filter\` |"
    rule="|---|"
    while read -r lod _; do
      header+=" LOD $lod |"
      rule+="---:|"
    done <"$OUT/exact.tsv"
    echo "${header/LOD all/LODs 1+}"
    echo "$rule"
    for run in exact fast; do
      label=$([ $run = exact ] && echo "exact (LOD 0 copied)" || echo "\`--fast-shrink\`")
      echo "| $label |$(awk '{ printf " %s / %s |", $2, $3 }' "$OUT/$run.tsv")"
    done
    echo
  done
  rm -rf "$OUT/reference" "$OUT/exact" "$OUT/fast"

  log "timing, $RUNS runs each"
  : >"$OUT/runs.tsv"
  for ((i = 0; i < RUNS; i++)); do
    for layout in dzi pack; do
      for run in exact fast; do
        rm -rf "$OUT/t" "$OUT/t.vtpk"
        case $layout in
          dzi) dest=(-o "$OUT/t" "${DZ[@]}") ;;
          pack) dest=(--pack "$OUT/t.vtpk" --tile-size 256 --border 0 -q) ;;
        esac
        flag=()
        [ $run = fast ] && flag=(--fast-shrink)
        read -r wall rss <<<"$(measure "$OUT/run.log" "$VT" split "$SLIDE" "${dest[@]}" "${flag[@]}")"
        cpu=$(awk -F': ' '/User time/ { u = $2 } /System time/ { s = $2 } END { printf "%.2f", u + s }' "$WORK/time.txt")
        printf '%s\t%s\t%s\t%s\n' "$layout-$run" "$wall" "$cpu" "$rss" >>"$OUT/runs.tsv"
      done
    done
  done
  rm -rf "$OUT/t" "$OUT/t.vtpk"
  echo "| $SIZE slide, default filter | wall (s) | CPU (s) | CPU / wall | peak (MiB) | time vs exact |"
  echo "|---|---:|---:|---:|---:|---:|"
  for layout in dzi pack; do
    exact_wall=$(median "$OUT/runs.tsv" "$layout-exact" 2)
    for run in exact fast; do
      wall=$(median "$OUT/runs.tsv" "$layout-$run" 2)
      cpu=$(median "$OUT/runs.tsv" "$layout-$run" 3)
      rss=$(median "$OUT/runs.tsv" "$layout-$run" 4)
      name=$([ $layout = dzi ] && echo "Deep Zoom" || echo "pack")
      label=$([ $run = exact ] && echo "$name, exact" || echo "$name, \`--fast-shrink\`")
      awk -v l="$label" -v w="$wall" -v c="$cpu" -v r="$rss" -v e="$exact_wall" \
        'BEGIN { printf "| %s | %.2f | %.2f | %.2f | %.0f | %.2fx |\n", l, w, c, c / w, r / 1024, w / e }'
    done
  done
  echo
  echo "Medians of $RUNS runs, alternating."
} | tee "$OUT/report.md"
splice fast-shrink "$OUT/report.md" ""
