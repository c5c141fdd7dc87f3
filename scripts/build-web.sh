#!/usr/bin/env bash
# Builds the web viewer (web/viewer/, docs/web-runtime.md) into OUT_DIR: index.html, viewer.js,
# the wasm module (vortex_web_bg.wasm) and wasm-bindgen's glue (vortex_web.js). A static
# directory: any web server shows it, `index.html?pack=URL` opens a pack.
#
# Installs what it needs, once: the wasm32-unknown-unknown target (rustup) and the wasm-bindgen
# CLI at the version of the wasm-bindgen crate in Cargo.lock (its output must match the crate's),
# under target/wasm-tools so that CI caches it with target/.
set -euo pipefail

out=${1:?usage: scripts/build-web.sh OUT_DIR}
root=$(cd "$(dirname "$0")/.." && pwd)
cd "$root"

rustup target list --installed | grep -qx wasm32-unknown-unknown || rustup target add wasm32-unknown-unknown

# The version of the crate the module is built with: the CLI must be the same.
version=$(awk '/^name = "wasm-bindgen"$/ { getline; gsub(/[^0-9.]/, ""); print; exit }' Cargo.lock)
tools=target/wasm-tools
bindgen=$tools/bin/wasm-bindgen
if ! { [ -x "$bindgen" ] && "$bindgen" --version | grep -q " $version\$"; }; then
    cargo install wasm-bindgen-cli --version "=$version" --root "$tools"
fi

# Release: the debug module is several times larger and slower.
cargo build -p vortex-web --target wasm32-unknown-unknown --release
mkdir -p "$out"
"$bindgen" --target web --no-typescript --out-dir "$out" target/wasm32-unknown-unknown/release/vortex_web.wasm
cp web/viewer/index.html web/viewer/viewer.js "$out/"
echo "web viewer in $out: $(du -sh "$out" | cut -f1); open index.html?pack=URL" >&2
