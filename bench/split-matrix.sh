#!/usr/bin/env bash
# bench/split-matrix.sh: how busy `split --pack` keeps the cores, for every kind of source and
# every codec (issue 18), and which stage bounds each run.
#
# The 16384² RGB image of bench/split-vs-vips.sh (src16k.tif, an uncompressed strip BigTIFF;
# generated if missing) is saved by Debian's vips as six more sources: a tiled TIFF (256²
# tiles), Deflate and LZW strip TIFFs, a PNG (zlib level 1), a baseline JPEG (Q90) and a PPM.
# A seventh, `tiles`, is the same image as 4096 256-texel JPEG tiles (Q90, a directory), which
# `convert` reads instead of `split`. Each source is cut by `split --pack --tile-size 256
# --border 0` (default filter) with each codec: jpeg (Q85), png (fast), raw, zstd, bc1, bc7 (ultra-fast). Per run, from /usr/bin/time
# -v: wall time, CPU time (user + sys) and their ratio (2.0 would be both cores busy the whole
# run), CPU milliseconds per source megapixel (the work, whatever the cores: compare it with the
# peer's), throughput in source megapixels per second and peak memory; from `split --json`'s
# `stages`: the time reading the source, the producer's pyramid sums and the cutting thread's
# cutting, the time the cutter waited for the encoders and the time they waited for it. A run
# whose encoders waited longer than the cutter did is bound by the busiest of the serial threads
# (reading, pyramid, cutting), the other way round by the encoders. As a peer, libvips 8.18 (pyvips-binary from PyPI, in
# bench/work/venv) writes each source as 256-texel JPEG tiles (Q85) into a .zip, the nearest it
# has to one pack file. RUNS runs per cell (default 5), alternating tools; medians. By default
# only the JPEG codec, the one the peer writes too (issue 28's goals); CODECS adds the others.
# *held* is what the stages held at most by their own count (`split --json`'s
# `memory.peakBytes`), beside the peak RSS.
# `jtiff` is the image as a JPEG-tiled BigTIFF (256² tiles, Q90: RGB, as libvips writes from
# Q90 on), whose tiles the pack copies into its finest level (issue 45); `jtiff-fast` cuts it with
# `--fast-shrink` (docs/accuracy.md). `slide` is bench/lib.sh's 16384² slide (make_slide), its
# tiles copied too. `jtiff-dzi` and `slide-dzi` write Deep Zoom directories (256-texel tiles, no
# overlap) instead of a pack, and the peer dzsave's directory instead of a .zip: each run on a
# new ext4 mounted through a loop device where root can (bench/lib.sh's new_ext4), since on this
# machine's disk creating files measures recent deletions too (bench/create-files.sh).
# Two more rows cut the strip BigTIFF as issue 28's goals name them: `strip-box` with
# `--filter box` (libvips' own 2x2 mean), `strip-border1` with the default border of 1 (the peer
# then writes 254-texel tiles with an overlap of 1: the same 256-texel files).
# A second table gives the CPU time per source megapixel, ours by stage from `split --json`'s
# `stages.cpu` (read, the pyramid's sums, cutting, encoding, storing, and *other*: the rest of
# the process's CPU, mostly a compressed TIFF's strip workers), the peer's whole; and the wall
# time over the encode floor (the encoders' CPU time divided by the cores). For the peer's CPU by
# kind of work, see `bench/split-profile.sh peer SOURCE`.
#
# Results go to docs/benchmarks.md (or $DOC) between `<!-- split-matrix:begin -->` and `:end -->`.
#     bench/split-matrix.sh                 # JPEG rows, 5 runs: about 7 minutes on 2 quiet cores
#                                           # (and 2 more the first time, making 6 GB of sources)
#     RUNS=1 CODECS="jpeg png raw zstd bc1 bc7" bench/split-matrix.sh   # every codec, one run each
#     SOURCES="strip jpeg" CODECS="jpeg png" bench/split-matrix.sh
#     REPORT_ONLY=1 bench/split-matrix.sh   # the table again from the last runs (bench/work/matrix/runs.tsv)
#     OUT_DIR=/dev/shm DOC=/tmp/shm.md SOURCES=strip CODECS=jpeg bench/split-matrix.sh
#                                           # outputs on tmpfs: what the disk's writeback costs
set -euo pipefail
cd "$(dirname "$0")/.."
source bench/lib.sh
RUNS=${RUNS:-5}
SOURCES=${SOURCES:-strip strip-box strip-border1 tiled jtiff jtiff-fast jtiff-dzi slide slide-dzi deflate lzw png jpeg ppm tiles}
CODECS=${CODECS:-jpeg}
bench_setup
SRC=$WORK/src16k.tif
M=$WORK/matrix
OUT=${OUT_DIR:-$M} # where the packs (and the peer's .zip) are written
mkdir -p "$M" "$OUT"
pyvips_setup # PY and PYVIPS_VERSION ("libvips-8.18.7"), both empty without the peer: its column stays empty

# source NAME: the path of that source, made from src16k.tif the first time.
source_file() {
  local f
  case $1 in
    strip | strip-box | strip-border1) echo "$SRC"; return ;;
    tiled) f=$M/tiled.tif; [ -s "$f" ] || vips tiffsave "$SRC" "$f" --tile --tile-width 256 --tile-height 256 --bigtiff ;;
    jtiff | jtiff-fast | jtiff-dzi) f=$(jpeg_tiled_source) ;;
    slide | slide-dzi)
      [ -n "$PY" ] || { echo "error: the slide rows need pyvips to make the slide (bench/lib.sh's make_slide)" >&2; exit 1; }
      f=$WORK/slide-16384x16384.tif
      make_slide 16384 16384 "$f"
      ;;
    deflate) f=$M/deflate.tif; [ -s "$f" ] || vips tiffsave "$SRC" "$f" --compression deflate --bigtiff ;;
    lzw) f=$M/lzw.tif; [ -s "$f" ] || vips tiffsave "$SRC" "$f" --compression lzw --bigtiff ;;
    png) f=$M/src.png; [ -s "$f" ] || vips pngsave "$SRC" "$f" --compression 1 ;;
    jpeg) f=$M/src.jpg; [ -s "$f" ] || vips jpegsave "$SRC" "$f" --Q 90 ;;
    ppm) f=$M/src.ppm; [ -s "$f" ] || vips ppmsave "$SRC" "$f" ;;
    tiles)
      f=$M/tiles256
      [ -s "$f/info.json" ] || "$WORK/bin/vortex-tiler" split "$SRC" -o "$f" --tile-size 256 --border 0 --codec jpeg \
        --quality 90 --filter box -q
      ;;
    *) echo "error: unknown source $1" >&2; exit 1 ;;
  esac
  echo "$f"
}

# codec_args CODEC SOURCE: the flags of CODEC. JPEG's Q85 is the default: asked for explicitly,
# it would re-encode the stored tiles of the JPEG-tiled sources and the slide, which their rows copy.
codec_args() {
  case $1 in
    jpeg) [[ $2 == jtiff* || $2 == slide* ]] && echo "--codec jpeg" || echo "--codec jpeg --quality 85" ;;
    png) echo "--codec png --png-compression fast" ;;
    bc7) echo "--codec bc7 --bc7-effort ultra-fast" ;;
    *) echo "--codec $1" ;;
  esac
}

# Deep Zoom rows (`*-dzi`) write 5,470 files a run: on a new file system each run where one can be
# mounted (bench/lib.sh's new_ext4), else into directories kept until the end (never where
# files were just deleted).
DIRS=
! can_mount || DIRS=$M/mnt
# output_args NAME ours|peer: where that run writes (ours: the flags; the peer: its destination),
# the file system made first for a Deep Zoom row.
output_args() {
  if [[ $1 == *-dzi ]]; then
    local dest=$OUT/dzi-$2-$RANDOM
    [ -z "$DIRS" ] || { new_ext4 "$DIRS" >&2; dest=$DIRS/dzi; }
    [ "$2" = ours ] && echo "--layout dzi -o $dest/out" || echo "$dest/peer"
  else
    [ "$2" = ours ] && echo "--pack $OUT/out.vtpk --force" || echo "$OUT/peer.zip"
  fi
}
# discard_output NAME ours|peer: the run's output removed (a Deep Zoom directory stays to the end
# where no file system can be mounted).
discard_output() {
  if [[ $1 == *-dzi ]]; then [ -z "$DIRS" ] || drop_ext4 "$DIRS"; else rm -f "$OUT/out.vtpk" "$OUT/peer.zip"; fi
}

RAW=$M/runs.tsv
# run ID COMMAND...: times one run, appends "ID wall cpu rss json" to $RAW. A failed run stops the
# script, except the peer's (libvips from PyPI reads no PPM): that cell stays empty.
run() {
  local id=$1
  shift
  sync
  if ! /usr/bin/time -v -o "$M/time.txt" "$@" >"$M/out.json" 2>"$M/err.txt"; then
    case $id in
      *peer) echo "note: $id failed, left out: $(tail -1 "$M/err.txt")" >&2; return ;;
      *) cat "$M/err.txt" >&2; exit 1 ;;
    esac
  fi
  local wall user sys rss
  wall=$(sed -n 's/^[[:space:]]*Elapsed (wall clock) time (h:mm:ss or m:ss): //p' "$M/time.txt" |
    awk -F: '{ s = 0; for (i = 1; i <= NF; i++) s = s * 60 + $i; printf "%.2f", s }')
  user=$(sed -n 's/^[[:space:]]*User time (seconds): //p' "$M/time.txt")
  sys=$(sed -n 's/^[[:space:]]*System time (seconds): //p' "$M/time.txt")
  rss=$(sed -n 's/^[[:space:]]*Maximum resident set size (kbytes): //p' "$M/time.txt")
  printf '%s\t%s\t%s\t%s\t%s\n' "$id" "$wall" "$(calc %.2f "$user + $sys")" "$rss" "$(tr -d '\n' <"$M/out.json")" >>"$RAW"
}

[ "${REPORT_ONLY:-0}" = 1 ] && SOURCES_RUN= || SOURCES_RUN=$SOURCES
[ -z "$SOURCES_RUN" ] || : >"$RAW"
for name in $SOURCES_RUN; do
  log "source $name"
  file=$(source_file "$name")
  find "$file" -type f -exec cat {} + >/dev/null # in the page cache: this measures decoding, not the disk
  command=split
  [ "$name" = tiles ] && command=convert
  for round in $(seq "$RUNS"); do
    for codec in $CODECS; do
      # shellcheck disable=SC2046 # output_args, codec_args and split_variant_args are word-split on purpose
      run "$name $codec" "$WORK/bin/vortex-tiler" "$command" "$file" $(output_args "$name" ours) --tile-size 256 \
        $(split_variant_args "$name") $(codec_args "$codec" "$name") --json
      discard_output "$name" ours
    done
    if [ -n "$PY" ] && [ "$name" != tiles ]; then
      # shellcheck disable=SC2046 # peer_grid is word-split on purpose
      run "$name peer" "$PY" -c "$PEER_DZSAVE" "$file" "$(output_args "$name" peer)" $(peer_grid "$name")
      discard_output "$name" peer
    fi
  done
done
[ -z "$DIRS" ] || drop_ext4 "$DIRS"
rm -rf "$OUT"/dzi-*

REPORT=$M/report.md
python3 - "$RAW" "$PYVIPS_VERSION" "$REV" "$SOURCES" "$CODECS" >"$REPORT" <<'PY'
import json, statistics, sys, datetime, os
raw, peer_version, rev, sources, codecs = sys.argv[1], sys.argv[2], sys.argv[3], sys.argv[4].split(), sys.argv[5].split()
runs = {}
for line in open(raw):
    rid, wall, cpu, rss, out = line.rstrip("\n").split("\t", 4)
    runs.setdefault(rid, []).append((float(wall), float(cpu), int(rss), out))
def median(rid):
    rs = sorted(runs[rid], key=lambda r: r[0])
    return rs[len(rs) // 2]
def cells():
    """Per source: its peer's median run (or None) and, per codec run, the codec and its median
    run; cells missing from runs.tsv (REPORT_ONLY on runs made with other SOURCES or CODECS) left out."""
    for s in sources:
        peer = median(f"{s} peer") if f"{s} peer" in runs else None
        yield s, peer, [(c, median(f"{s} {c}")) for c in codecs if f"{s} {c}" in runs]
mpx = 16384 * 16384 / 1e6
print(f"{datetime.date.today()}, {os.cpu_count()} cores, vortex-tiler {rev}"
      + (f", peer {peer_version} (pyvips-binary, direct mode: `Q=85`) writing a .zip of 256-texel JPEG tiles" if peer_version else "")
      + "; `split --pack --tile-size 256 --border 0`, default filter (`strip-box`: `--filter box`; `jtiff-fast`: `--fast-shrink`; `strip-border1`: `--border 1`,"
      + " the peer's tiles 254 texels with an overlap of 1; `-dzi`: `--layout dzi --overlap 0` and the peer's dzsave to a directory, each run on a new ext4)"
      + "; the median of the runs per cell.")
print()
print("| source | codec | wall | CPU | CPU / wall | CPU ms / Mpx | Mpx/s | peak RSS | held | read | waits for rows | pyramid | cut | waits for encoders | encoders wait | encode | store | bound by | vs peer |")
print("|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---|---:|")
for s, peer, ours in cells():
    for c, (wall, cpu, rss, out) in ours:
        doc = json.loads(out)
        st = doc["stages"]
        # What the stages held at most by their own count (runs before `memory` existed: blank).
        held = doc.get("memory", {}).get("peakBytes")
        held = f"{held / 2**20:.0f} MiB" if held is not None else ""
        if st["encodersIdleSeconds"] <= st["producerBlockedSeconds"]:
            bound = "storing" if st["storeSeconds"] > st["encodeSeconds"] else "encoders"
        else:
            serial = {"reading": st["readSeconds"], "pyramid": st["pyramidSeconds"], "cutting": st.get("cutSeconds", 0)}
            bound = max(serial, key=serial.get)
        vs = f"{peer[0] / wall:.2f}x" if peer and c == "jpeg" else ""
        print(f"| {s} | {c} | {wall:.2f} s | {cpu:.2f} s | {cpu / wall:.2f} | {cpu / mpx * 1e3:.1f} | {mpx / wall:.0f} | {rss / 1024:.0f} MiB | {held} "
              f"| {st['readSeconds']:.2f} | {st.get('readWaitSeconds', 0):.2f} | {st['pyramidSeconds']:.2f} | {st.get('cutSeconds', 0):.2f} | {st['producerBlockedSeconds']:.2f} "
              f"| {st['encodersIdleSeconds']:.2f} | {st['encodeSeconds']:.2f} | {st['storeSeconds']:.2f} | {bound} | {vs} |")
    if peer:
        print(f"| {s} | peer: libvips {'Deep Zoom' if s.endswith('-dzi') else '.zip'} (JPEG) | {peer[0]:.2f} s | {peer[1]:.2f} s | {peer[1] / peer[0]:.2f} | {peer[1] / mpx * 1e3:.1f} | {mpx / peer[0]:.0f} "
              f"| {peer[2] / 1024:.0f} MiB | | | | | | | | | | | |")
print()
print("CPU milliseconds per source megapixel, by stage (`split --json`'s `stages.cpu`, the same median runs); *other* is the rest of the process's CPU.")
print()
print("| source | codec | CPU ms / Mpx | read | decode | sums | cut | encode | store | other | wall / encode floor | CPU vs peer |")
print("|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|")
cores = os.cpu_count() or 1
ms = lambda seconds: f"{seconds / mpx * 1e3:.1f}"
for s, peer, ours in cells():
    for c, (wall, cpu, rss, out) in ours:
        st = json.loads(out)["stages"].get("cpu")
        vs = f"{cpu / peer[1]:.2f}" if peer and c == "jpeg" else ""
        if not st:  # runs from before stages.cpu, or a platform without thread CPU clocks
            print(f"| {s} | {c} | {ms(cpu)} | | | | | | | | | {vs} |")
            continue
        # decodeSeconds: a source's tiles decoded on the pool (runs from before it: 0).
        names = ["readSeconds", "decodeSeconds", "pyramidSeconds", "cutSeconds", "encodeSeconds", "storeSeconds"]
        floor = st["encodeSeconds"] / cores
        over_floor = f"{wall / floor:.2f}" if floor > 0 else ""
        other = max(cpu - sum(st.get(n, 0) for n in names), 0)
        cells = " | ".join(ms(st.get(n, 0)) for n in names)
        print(f"| {s} | {c} | {ms(cpu)} | {cells} | {ms(other)} | {over_floor} | {vs} |")
    if peer:
        print(f"| {s} | peer | {ms(peer[1])} | | | | | | | | | |")
PY
cat "$REPORT"
splice split-matrix "$REPORT" "## Every source with every codec: how busy split keeps the cores (\`bench/split-matrix.sh\`)

Stage times are seconds of wall time from \`split --json\`'s \`stages\`: a thread reads and
decodes the source (*read*); the producer thread waits for its rows (*waits for rows*) and makes
the pyramid's sums (*pyramid*); a cutting thread cuts tiles out of the levels (*cut*) and waits
when the encoders have not taken the last batch (*waits for encoders*); the encoders wait when it
has none ready (*encoders wait*); *store* is the pack writer's ordered part on one thread. *Bound
by*: the encoders (or storing, where it took longer than encoding) where the cutter waited for
them longer than they for it, else the busiest of reading, the pyramid and cutting. *Held*: what
the stages held at most by their own count (\`split --json\`'s \`memory.peakBytes\`, docs/cli.md);
the rest of the peak RSS is code, stacks, tables and the allocator's. The
\`tiles\` source is 4096 JPEG tiles, read by \`convert\`; \`jtiff\` a JPEG-tiled BigTIFF whose
tiles the pack copies (\`jtiff-fast\`: with \`--fast-shrink\`); \`slide\` a slide-like pyramidal
TIFF of the same size (bench/lib.sh's make_slide: 256-texel JPEG tiles at Q90), its tiles copied
too. The \`-dzi\` rows write Deep Zoom directories instead of a pack (the peer: dzsave into a
directory), each run on a new file system: on this machine's disk a run creating files just
after others were deleted measures that deletion too (\`bench/create-files.sh\`).
*vs peer*: libvips' wall time over ours, JPEG only. In the CPU table, *read*, *decode* (a JPEG
TIFF's tiles decoded on the pool), *sums*, *cut*, *encode* and *store* are each stage's CPU time
by its thread's CPU clock (\`split --json\`'s
\`stages.cpu\`), *other* the rest of the process's (a compressed TIFF's strip workers, the
encoders' caller, start and end); *wall / encode floor* the wall time over the encoders' CPU
time divided by the cores (issue 28's goal: at most 1.25); *CPU vs peer* our CPU time over
libvips' (goal: at most 1). \`bench/split-profile.sh peer SOURCE\` splits the peer's CPU by kind
of work."
