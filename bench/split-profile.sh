#!/usr/bin/env bash
# bench/split-profile.sh: where one cell of bench/split-matrix.sh spends its CPU, per thread
# (issue 18). Samples `split --pack` of a source with a codec under `perf record` and prints,
# per thread, its CPU seconds and its busiest symbols; then the whole run's CPU per 100 ms
# (2.0 = both cores busy), which shows where the cores idle: at the start, the end, or all
# along. Needs `perf` (Debian: linux-perf) and the matrix's sources (made by split-matrix.sh).
#     bench/split-profile.sh strip jpeg
#     bench/split-profile.sh png raw
#     OUT_DIR=/dev/shm bench/split-profile.sh strip jpeg   # the pack on tmpfs: no disk
#
# `peer SOURCE` instead profiles the matrix's JPEG cell of SOURCE (strip, strip-box,
# strip-border1, tiled, ...) and libvips 8.18's run of the same source, and prints the CPU
# milliseconds per source megapixel of each by kind of work, side by side (issue 28): libvips
# has no stage clock, so its CPU is split by the symbols the samples fall in (and, in the
# kernel, by the call chain: reading the file, writing the output, page faults). Its library
# is stripped: samples in code without a name are JPEG encoding where a calibration run, which
# only encodes JPEG tiles from memory, sampled the same code; the rest stays *unnamed*.
#     bench/split-profile.sh peer strip
set -euo pipefail
cd "$(dirname "$0")/.."
source bench/lib.sh
[ $# = 2 ] || { echo "usage: $0 SOURCE CODEC | $0 peer SOURCE (sources: strip tiled deflate lzw png jpeg ppm; codecs as split-matrix.sh)" >&2; exit 2; }
command -v perf >/dev/null || { echo "error: no perf (apt-get install linux-perf)" >&2; exit 1; }
M=$WORK/matrix
OUT=${OUT_DIR:-$M}
mkdir -p "$OUT"
[ "$1" = peer ] && { peer_mode=$2; set -- "$2" jpeg; } || peer_mode=
case $1 in
  strip | strip-box | strip-border1) src=$WORK/src16k.tif ;;
  tiled | deflate | lzw) src=$M/$1.tif ;;
  png | jpeg | ppm) src=$M/src.$([ "$1" = jpeg ] && echo jpg || echo "$1") ;;
  *) echo "error: unknown source $1" >&2; exit 2 ;;
esac
[ -s "$src" ] || { echo "error: $src is missing: run bench/split-matrix.sh first" >&2; exit 1; }
case $2 in
  jpeg) codec=(--codec jpeg --quality 85) ;;
  png) codec=(--codec png --png-compression fast) ;;
  bc7) codec=(--codec bc7 --bc7-effort ultra-fast) ;;
  *) codec=(--codec "$2") ;;
esac
bin=${VORTEX:-$WORK/bin/vortex-tiler}
[ -x "$bin" ] || { echo "error: $bin is missing: run bench/split-matrix.sh first (or set VORTEX)" >&2; exit 1; }

# families RUN.perf MPX [CALIBRATION.perf]: CPU ms per source Mpx by kind of work, one
# "family<TAB>ms" line each, from `perf script` of a run sampled with kernel call chains.
families() {
  perf script -i "$1" -F ip,sym,dso 2>/dev/null | python3 -c '
import collections, re, subprocess, sys
HZ = 999
mpx = float(sys.argv[1])
def samples(lines):
    """Each sample as its frames, leaf first: (address, symbol, library file name)."""
    frames = []
    for line in lines:
        line = line.strip()
        if not line:
            if frames:
                yield frames
            frames = []
            continue
        ip, _, rest = line.partition(" ")
        sym, _, dso = rest.rpartition(" (")
        frames.append((ip, sym.strip(), dso.rstrip(")").rsplit("/", 1)[-1]))
    if frames:
        yield frames
def unnamed_vips(frames):
    ip, sym, dso = frames[0]
    return dso.startswith("libvips") and sym.startswith("[unknown]")
# The stripped libvips code a JPEG-only run sampled, in 64-byte blocks: JPEG encoding.
jpeg_blocks = set()
if len(sys.argv) > 2:
    out = subprocess.run(["perf", "script", "-i", sys.argv[2], "-F", "ip,sym,dso"], capture_output=True, text=True).stdout
    jpeg_blocks = {int(f[0][0], 16) >> 6 for f in samples(out.splitlines()) if unnamed_vips(f)}
KERNEL = [
    ("read", r"filemap_read|vfs_read|ksys_read|filemap_fault|page_cache_ra|readahead"),
    ("write", r"vfs_write|ksys_write|ext4_|iomap_|writeback|sync_file_range|fsync|do_truncate|jbd2"),
    ("page faults, memory", r"exc_page_fault|handle_mm_fault|clear_page|do_anonymous_page|unmap|munmap|mmap"),
]
USER = [
    # Decoding a JPEG source comes before encoding: both are libjpeg-turbo.
    ("read", r"idct|ycc_rgb|upsample|decode_mcu|decompress|jpeg_read|fill_bit_buffer|vortex_tiler::source|vortex_tiler::decode|"
             r"tiff::|png::|fdeflate|zune|inflate|weezl|TIFF|rtiff|vips_foreign_load"),
    ("JPEG encode", r"jsimd_|encode_mcu|forward_DCT|fdct|rgb_ycc|downsample|compress_data|jpeg_|emit_|dump_buffer|finish_pass|"
                    r"quantize|huff|jcopy|pre_process_data|process_data_simple_main|jinit_|start_pass|vortex_tiler::codec"),
    ("shrink (pyramid sums)", r"pyramid::(sums|reduce|filter)|feed_exact|reciprocal|Sums|Reducer|ExactFilter|ExactRow|vips_region_shrink|vips_shrink|shrink"),
    ("cut, copy", r"pyramid::(cut|band)|Cuts|replay|memcpy|memmove|memset|vips_region_copy|vips__region_copy"),
    ("allocator", r"malloc|free|_int_|realloc|calloc|tcache|arena|mmap_chunk"),
    ("write", r"vortex_pack|crc32|sink::|zip::|archive|deflate|vips_target|xxh|libc_write|__write|pwrite"),
    # What reading the clocks of src/stages.rs costs: ours only.
    ("stage clocks", r"clock_gettime|StageClock|Instant>::now"),
    ("start-up (interpreter, loader)", r"^_?Py|^py|_dl_|do_lookup_x|dl_main"),
]
STARTUP = ("libpython", "python3", "ld-linux", "_libvips")
count, other = collections.Counter(), collections.Counter()
for frames in samples(sys.stdin):
    ip, sym, dso = frames[0]
    family = "other"
    if dso.startswith("[kernel"):
        chain = " ".join(s for _, s, d in frames if d.startswith("[kernel"))
        family = next((f for f, pattern in KERNEL if re.search(pattern, chain)), "kernel, other")
    elif dso.startswith(STARTUP):
        family = "start-up (interpreter, loader)"
    elif unnamed_vips(frames):
        family = "JPEG encode" if int(ip, 16) >> 6 in jpeg_blocks else "libvips, unnamed"
    else:
        family = next((f for f, pattern in USER if re.search(pattern, sym)), "other")
    count[family] += 1
    if family == "other":
        other[f"{sym[:40]} ({dso[:16]})"] += 1
in_other = max(count["other"], 1)
top = ", ".join(f"{s} {n / in_other:.0%}" for s, n in other.most_common(5))
print(f"what \"other\" is most: {top}", file=sys.stderr)
for family, n in count.most_common():
    print(f"{family}\t{n / HZ / mpx * 1e3:.2f}")
print(f"total\t{sum(count.values()) / HZ / mpx * 1e3:.2f}")
' "$2" ${3:+"$3"}
}

# peer_profile NAME: our JPEG cell of NAME and the peer's run of the same source, by family.
peer_profile() {
  local name=$1 mpx
  export VIPS_WARNING=0 # vipsheader 8.14 warns about the TIFF Predictor tag the tiff crate writes
  pyvips_setup
  [ -n "$PY" ] || { echo "error: no libvips 8.18 peer (pyvips)" >&2; exit 1; }
  mpx=$(vipsheader -f width "$src" | awk -v h="$(vipsheader -f height "$src")" '{ print $1 * h / 1e6 }')
  sync
  # shellcheck disable=SC2046 # split_variant_args is word-split on purpose
  perf record -q -F 999 -g -o "$WORK/ours.perf" -- "$bin" split "$src" --pack "$OUT/profile.vtpk" --force \
    --tile-size 256 $(split_variant_args "$name") "${codec[@]}" -q
  rm -f "$OUT/profile.vtpk" "$OUT/peer.zip"
  sync
  # shellcheck disable=SC2046 # peer_grid is word-split on purpose
  perf record -q -F 999 -g -o "$WORK/peer.perf" -- "$PY" -c "$PEER_DZSAVE" "$src" "$OUT/peer.zip" $(peer_grid "$name")
  rm -f "$OUT/peer.zip"
  # Calibration: libvips encoding 256-texel JPEG tiles (Q85) from memory, sampled only once
  # the source's first 2048 rows are in memory (perf starts disabled, the script enables it).
  local ctl=$WORK/perf-ctl.fifo
  rm -f "$ctl" && mkfifo "$ctl"
  perf record -q -F 999 -g -D -1 --control "fifo:$ctl" -o "$WORK/calibration.perf" -- "$PY" -c '
import sys, time, pyvips
im = pyvips.Image.new_from_file(sys.argv[1], access="sequential")
im = im.crop(0, 0, min(im.width, 4096), min(im.height, 2048)).copy_memory()
with open(sys.argv[2], "w") as ctl:
    ctl.write("enable\n")
# Two CPU-seconds of encoding: enough samples to cover the code JPEG encoding runs.
started = time.process_time()
while time.process_time() < started + 2:
    for y in range(0, im.height - 255, 256):
        for x in range(0, im.width - 255, 256):
            im.crop(x, y, 256, 256).jpegsave_buffer(Q=85)
' "$src" "$ctl"
  rm -f "$ctl"
  log "CPU ms per source Mpx by kind of work, $name ($mpx Mpx), ours and libvips $PYVIPS_VERSION's"
  join -t $'\t' -a 1 -a 2 -e "" -o 0,1.2,2.2 <(families "$WORK/ours.perf" "$mpx" | sort) \
    <(families "$WORK/peer.perf" "$mpx" "$WORK/calibration.perf" | sort) |
    awk -F'\t' 'BEGIN { printf "%-32s %8s %8s\n", "family", "ours", "libvips" }
      { printf "%-32s %8s %8s\n", $1, $2, $3 }'
}
cat "$src" >/dev/null # in the page cache
[ -z "$peer_mode" ] || { peer_profile "$peer_mode"; exit; }
rm -f "$OUT/profile.vtpk"
sync
perf record -q -F 999 -o "$WORK/profile.data" -- "$bin" split "$src" --pack "$OUT/profile.vtpk" --force \
  --tile-size 256 --border 0 "${codec[@]}" --json >"$WORK/profile.json"
rm -f "$OUT/profile.vtpk"
perf script -i "$WORK/profile.data" -F comm,tid,time,ip,sym 2>/dev/null | python3 -c '
import collections, json, sys
HZ = 999
run = json.load(open(sys.argv[1]))
mpx = run["width"] * run["height"] / 1e6
threads, symbols, buckets = collections.Counter(), collections.defaultdict(collections.Counter), collections.Counter()
names, start = {}, None
for line in sys.stdin:
    parts = line.split()
    if len(parts) < 3:
        continue
    # comm tid time: ip sym (the thread name may hold spaces: the tid is the first number)
    i = next(k for k, p in enumerate(parts) if p.isdigit())
    comm, tid, t = " ".join(parts[:i]), parts[i], float(parts[i + 1].rstrip(":"))
    sym = " ".join(parts[i + 3:]) or "?"
    start = t if start is None else start
    names[tid] = comm
    threads[tid] += 1
    symbols[tid][sym] += 1
    buckets[int((t - start) * 10)] += 1
total = sum(threads.values()) / HZ
print(f"{total:.2f} s of CPU sampled, {total / mpx * 1e3:.1f} ms per source Mpx")
for tid, n in threads.most_common():
    if n < HZ // 20:
        continue
    top = ", ".join(f"{s[:48]} {c / n:.0%}" for s, c in symbols[tid].most_common(4))
    print(f"  {names[tid]:>14} {n / HZ:5.2f} s: {top}")
print("cores busy per 100 ms:", " ".join(f"{buckets[b] / (HZ / 10):.1f}" for b in range(max(buckets) + 1)))
' "$WORK/profile.json"
